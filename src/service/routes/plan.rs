//! `POST /v1/plan`: image + target box → network prior → optimiser.
//!
//! Two encodings of the same request:
//! - `application/json`: `{"image_base64": "...", "target_box": [x1, y1, x2, y2],
//!   "mask_applied": false, ...scene and constraint fields of /v1/optimize}`;
//! - `multipart/form-data`: a part `image` (PNG or JPEG bytes) and a part
//!   `request` (the same JSON without `image_base64`).
//!
//! The scene and constraint fields (`promp`, `duration_s`, `start`, `goal`,
//! `obstacles`, `clearance_m`, `joint_limit_margin_rad`, `samples`,
//! `options`) are parsed by the optimiser's own request type, so they take
//! the same defaults and validation; `prior` is not accepted (it is what the
//! network predicts). The answer is the optimise response plus
//! `"prior": {"mean": [[T x dof]], "std": [[T x dof]]}` and `"model"`.

use super::optimize::{check_request_limits, record_solve, solve_control};
use crate::net::Model;
use crate::optim::{optimize_with, OptimizeRequest, OptimizeResponse};
use crate::promp::{Basis, WeightDistribution};
use crate::robot::Robot;
use crate::service::error::ApiError;
use crate::service::extract::{from_value, media_type, parse_json, read_body, MediaType};
use crate::service::image::{decode_base64, decode_image};
use crate::service::state::AppState;
use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::StatusCode;
use axum::Json;
use image::DynamicImage;
use nalgebra::DMatrix;
use serde::Serialize;
use serde_json::{Map, Value};
use std::sync::Arc;
use std::time::Instant;

/// Fields of a plan request that are not optimiser fields.
const IMAGE_FIELD: &str = "image_base64";
const BOX_FIELD: &str = "target_box";
const MASK_FIELD: &str = "mask_applied";

/// A parsed, validated plan request.
pub struct PlanInput {
    /// The decoded image.
    pub image: DynamicImage,
    /// Target berry box `[x1, y1, x2, y2]` in image pixels.
    pub target_box: [f64; 4],
    /// Whether the image already has the target painted (masked).
    pub mask_applied: bool,
    /// The optimiser request; its prior is replaced by the prediction.
    pub request: OptimizeRequest,
}

/// The predicted prior as trajectories (`T x dof`, rows are time samples).
#[derive(Debug, Serialize)]
pub struct PriorTrajectory {
    /// Mean joint positions.
    pub mean: Vec<Vec<f64>>,
    /// Standard deviation of the joint positions.
    pub std: Vec<Vec<f64>>,
}

/// Body of a `/v1/plan` answer.
#[derive(Debug, Serialize)]
pub struct PlanResponse {
    /// The optimiser's answer for the predicted prior.
    #[serde(flatten)]
    pub result: OptimizeResponse,
    /// The network's prior.
    pub prior: PriorTrajectory,
    /// Name of the model that predicted it.
    pub model: String,
}

/// `POST /v1/plan`.
pub async fn plan(
    State(state): State<AppState>,
    request: Request,
) -> Result<Json<PlanResponse>, ApiError> {
    let input = match media_type(request.headers()) {
        Some(MediaType::Json) => parse_json_request(&state, request).await?,
        Some(MediaType::Multipart) => parse_multipart_request(&state, request).await?,
        None => {
            return Err(ApiError::unsupported_media_type(
                "application/json or multipart/form-data",
            ))
        }
    };
    check_request_limits(state.config(), &input.request)?;
    let model = state.model().ok_or_else(ApiError::model_unavailable)?;
    let robot = state.robot();
    let deadline = Instant::now() + state.config().deadline;
    let response = state
        .limiter()
        .run(deadline, move |job| {
            predict_and_optimize(&model, &robot, input, &solve_control(job))
        })
        .await??;
    record_solve(&state, &response.result);
    Ok(Json(response))
}

/// The blocking part: network prior, then the optimiser (also used by
/// `dpmp plan`).
pub fn predict_and_optimize(
    model: &Arc<Model>,
    robot: &Arc<Robot>,
    input: PlanInput,
    ctl: &crate::optim::SolveControl,
) -> crate::Result<PlanResponse> {
    let prediction = model.predict(&input.image, input.target_box, input.mask_applied)?;
    let distribution = prediction.distribution;
    let mut request = input.request;
    let basis = Basis::new(&request.promp).map_err(|e| e.within("promp"))?;
    let expected = robot.dof() * basis.n_basis();
    if distribution.dim() != expected {
        return Err(crate::Error::invalid(
            "promp.n_basis",
            format!(
                "the model predicts {} weights = {} joints x {} basis functions; \
                 the request asks for {} x {}",
                distribution.dim(),
                robot.dof(),
                distribution.dim() / robot.dof().max(1),
                robot.dof(),
                basis.n_basis()
            ),
        ));
    }
    let prior = prior_trajectory(&distribution, &basis);
    request.prior = crate::optim::example::prior_spec(&distribution);
    let result = optimize_with(&request, robot, ctl)?;
    Ok(PlanResponse {
        result,
        prior,
        model: model.name().to_string(),
    })
}

fn prior_trajectory(d: &WeightDistribution, basis: &Basis) -> PriorTrajectory {
    PriorTrajectory {
        mean: rows(&d.trajectory_mean(basis)),
        std: rows(&d.trajectory_std(basis, 0.0)),
    }
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

async fn parse_json_request(state: &AppState, request: Request) -> Result<PlanInput, ApiError> {
    let bytes = read_body(request, state).await?;
    let mut fields: Map<String, Value> = parse_json(&bytes)?;
    let image_text = match fields.remove(IMAGE_FIELD) {
        Some(Value::String(text)) => text,
        Some(_) => return Err(ApiError::invalid(IMAGE_FIELD, "must be a base64 string")),
        None => {
            return Err(ApiError::invalid(
                IMAGE_FIELD,
                "missing: the PNG or JPEG image as base64",
            ))
        }
    };
    let bytes = decode_base64(IMAGE_FIELD, &image_text)?;
    finish_input(state, IMAGE_FIELD, &bytes, fields)
}

async fn parse_multipart_request(
    state: &AppState,
    request: Request,
) -> Result<PlanInput, ApiError> {
    let mut multipart = Multipart::from_request(request, state)
        .await
        .map_err(|e| multipart_error(e.status(), e.body_text()))?;
    let mut image: Option<Vec<u8>> = None;
    let mut fields: Option<Map<String, Value>> = None;
    while let Some(part) = multipart
        .next_field()
        .await
        .map_err(|e| multipart_error(e.status(), e.body_text()))?
    {
        let name = part.name().unwrap_or_default().to_string();
        let bytes = part
            .bytes()
            .await
            .map_err(|e| multipart_error(e.status(), e.body_text()))?;
        match name.as_str() {
            "image" if image.is_none() => image = Some(bytes.to_vec()),
            "request" if fields.is_none() => fields = Some(parse_json(&bytes)?),
            "image" | "request" => {
                return Err(malformed_multipart(&format!(
                    "the part `{name}` appears twice"
                )))
            }
            other => {
                return Err(malformed_multipart(&format!(
                    "unknown part `{other}`: expected `image` and `request`"
                )))
            }
        }
    }
    let image = image.ok_or_else(|| malformed_multipart("missing the part `image`"))?;
    let fields = fields.ok_or_else(|| malformed_multipart("missing the part `request`"))?;
    if fields.contains_key(IMAGE_FIELD) {
        return Err(ApiError::invalid(
            IMAGE_FIELD,
            "send the image either as the `image` part or as base64, not both",
        ));
    }
    finish_input(state, "image", &image, fields)
}

fn multipart_error(status: StatusCode, text: String) -> ApiError {
    if status == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::new(status, "body_too_large", text)
    } else {
        malformed_multipart(&text)
    }
}

fn malformed_multipart(message: &str) -> ApiError {
    ApiError::new(
        StatusCode::BAD_REQUEST,
        "malformed_multipart",
        format!("malformed multipart/form-data: {message}"),
    )
}

/// Validate the non-image fields, build the optimiser request with a
/// placeholder prior (replaced by the prediction), then decode the image.
fn finish_input(
    state: &AppState,
    image_field: &str,
    image_bytes: &[u8],
    mut fields: Map<String, Value>,
) -> Result<PlanInput, ApiError> {
    if fields.contains_key("prior") {
        return Err(ApiError::invalid(
            "prior",
            "/v1/plan predicts the prior from the image; send a prior to /v1/optimize instead",
        ));
    }
    let target_box = parse_box(fields.remove(BOX_FIELD))?;
    let mask_applied = match fields.remove(MASK_FIELD) {
        None => false,
        Some(Value::Bool(b)) => b,
        Some(_) => return Err(ApiError::invalid(MASK_FIELD, "must be true or false")),
    };
    fields.insert(
        "prior".to_string(),
        serde_json::json!({"mean": [], "cov": []}),
    );
    let request: OptimizeRequest = from_value(Value::Object(fields))?;
    let image = decode_image(image_field, image_bytes, state.config().max_image_pixels)?;
    check_box_inside(&target_box, &image)?;
    Ok(PlanInput {
        image,
        target_box,
        mask_applied,
        request,
    })
}

fn parse_box(value: Option<Value>) -> Result<[f64; 4], ApiError> {
    let value = value.ok_or_else(|| {
        ApiError::invalid(
            BOX_FIELD,
            "missing: the target box [x1, y1, x2, y2] in pixels",
        )
    })?;
    let numbers: Vec<f64> =
        from_value::<Vec<f64>>(value).map_err(|e| ApiError::invalid(BOX_FIELD, e.message))?;
    let b: [f64; 4] = numbers.as_slice().try_into().map_err(|_| {
        ApiError::invalid(
            BOX_FIELD,
            format!("expected 4 numbers [x1, y1, x2, y2], got {}", numbers.len()),
        )
    })?;
    crate::error::ensure_finite(BOX_FIELD, &b)?;
    if b[0] >= b[2] || b[1] >= b[3] {
        return Err(ApiError::invalid(
            BOX_FIELD,
            format!("needs x1 < x2 and y1 < y2, got {b:?}"),
        ));
    }
    Ok(b)
}

fn check_box_inside(b: &[f64; 4], image: &DynamicImage) -> Result<(), ApiError> {
    let (w, h) = (f64::from(image.width()), f64::from(image.height()));
    if b[0] < 0.0 || b[1] < 0.0 || b[2] > w || b[3] > h {
        return Err(ApiError::invalid(
            BOX_FIELD,
            format!("the box {b:?} is not inside the {w}x{h} image"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_are_validated_naming_the_field() {
        assert_eq!(
            parse_box(Some(serde_json::json!([1, 2, 3, 4]))).unwrap(),
            [1.0, 2.0, 3.0, 4.0]
        );
        for bad in [
            serde_json::json!([1, 2, 3]),
            serde_json::json!([3, 2, 1, 4]),
            serde_json::json!([1, 2, 3, "4"]),
            serde_json::json!("box"),
        ] {
            let e = parse_box(Some(bad.clone())).unwrap_err();
            assert_eq!(
                (e.status.as_u16(), e.field.as_deref()),
                (422, Some(BOX_FIELD)),
                "{bad}"
            );
        }
        assert_eq!(
            parse_box(None).unwrap_err().field.as_deref(),
            Some(BOX_FIELD)
        );
        let img = DynamicImage::new_rgb8(64, 48);
        assert!(check_box_inside(&[0.0, 0.0, 64.0, 48.0], &img).is_ok());
        assert!(check_box_inside(&[0.0, 0.0, 64.5, 48.0], &img).is_err());
    }
}
