//! `POST /v1/plan`: image (+ aligned depth) + target box → network prior
//! → (pre-grasp goal) → optimiser; the pipeline is [`crate::plan`].
//!
//! Two encodings of the same request:
//! - `application/json`: `{"image_base64": "...", "target_box": [x1, y1, x2, y2],
//!   "mask_applied": false, "depth_base64": "..." (optional 16-bit PNG),
//!   "depth_scale_m": 0.001, "target_position": [x, y, z] (optional, instead
//!   of depth), "goal_standoff_m": 0.1, ...scene and constraint fields of
//!   /v1/optimize}`;
//! - `multipart/form-data`: a part `image` (PNG or JPEG bytes), optionally a
//!   part `depth` (16-bit PNG) and a part `request` (the same JSON without
//!   `image_base64` and `depth_base64`).
//!
//! The scene and constraint fields (`promp`, `duration_s`, `start`, `goal`,
//! `obstacles`, `clearance_m`, `joint_limit_margin_rad`, `samples`,
//! `options`) are parsed by the optimiser's own request type, so they take
//! the same defaults and validation; `prior` is not accepted (it is what the
//! network predicts). The answer is the optimise response plus
//! `"prior": {"mean": [[T x dof]], "std": [[T x dof]]}`, `"model"` and,
//! with depth or a target position, `"target"`.

use super::optimize::{check_request_limits, record_solve, solve_control};
use crate::optim::OptimizeRequest;
use crate::perception::depth::{DepthImage, DEFAULT_DEPTH_SCALE_M};
use crate::plan::{
    check_target_position, predict_and_optimize, GoalApproach, PlanInput, PlanResponse, TargetInput,
};
use crate::service::error::ApiError;
use crate::service::extract::{from_value, media_type, parse_json, read_body, MediaType};
use crate::service::image::{decode_base64, decode_image};
use crate::service::state::AppState;
use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::StatusCode;
use axum::Json;
use image::DynamicImage;
use serde_json::{Map, Value};
use std::time::Instant;

/// Fields of a plan request that are not optimiser fields.
const IMAGE_FIELD: &str = "image_base64";
const BOX_FIELD: &str = "target_box";
const MASK_FIELD: &str = "mask_applied";
const DEPTH_FIELD: &str = "depth_base64";
const DEPTH_PART: &str = "depth";
const SCALE_FIELD: &str = "depth_scale_m";
const TARGET_FIELD: &str = "target_position";
const STANDOFF_FIELD: &str = "goal_standoff_m";

/// Encoded inputs of one request: (field naming it in errors, bytes).
struct Encoded {
    image: (&'static str, Vec<u8>),
    depth: Option<(&'static str, Vec<u8>)>,
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
    let image = (IMAGE_FIELD, decode_base64(IMAGE_FIELD, &image_text)?);
    let depth = match fields.remove(DEPTH_FIELD) {
        None | Some(Value::Null) => None,
        Some(Value::String(text)) => Some((DEPTH_FIELD, decode_base64(DEPTH_FIELD, &text)?)),
        Some(_) => return Err(ApiError::invalid(DEPTH_FIELD, "must be a base64 string")),
    };
    finish_input(state, Encoded { image, depth }, fields)
}

async fn parse_multipart_request(
    state: &AppState,
    request: Request,
) -> Result<PlanInput, ApiError> {
    let mut multipart = Multipart::from_request(request, state)
        .await
        .map_err(|e| multipart_error(e.status(), e.body_text()))?;
    let mut image: Option<Vec<u8>> = None;
    let mut depth: Option<Vec<u8>> = None;
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
            DEPTH_PART if depth.is_none() => depth = Some(bytes.to_vec()),
            "request" if fields.is_none() => fields = Some(parse_json(&bytes)?),
            "image" | DEPTH_PART | "request" => {
                return Err(malformed_multipart(&format!(
                    "the part `{name}` appears twice"
                )))
            }
            other => {
                return Err(malformed_multipart(&format!(
                    "unknown part `{other}`: expected `image`, `request` and optionally `depth`"
                )))
            }
        }
    }
    let image = image.ok_or_else(|| malformed_multipart("missing the part `image`"))?;
    let fields = fields.ok_or_else(|| malformed_multipart("missing the part `request`"))?;
    for (field, part) in [(IMAGE_FIELD, "image"), (DEPTH_FIELD, DEPTH_PART)] {
        if fields.contains_key(field) {
            return Err(ApiError::invalid(
                field,
                format!("send it either as the `{part}` part or as base64, not both"),
            ));
        }
    }
    let encoded = Encoded {
        image: ("image", image),
        depth: depth.map(|d| (DEPTH_PART, d)),
    };
    finish_input(state, encoded, fields)
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
/// placeholder prior (replaced by the prediction), then decode the image
/// and the depth.
fn finish_input(
    state: &AppState,
    encoded: Encoded,
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
    let scale = optional_number(&mut fields, SCALE_FIELD)?;
    if let Some(v) = scale.filter(|v| !(*v > 0.0 && *v <= 1.0)) {
        return Err(ApiError::invalid(
            SCALE_FIELD,
            format!("must be > 0 and <= 1 (m per depth unit), got {v}"),
        ));
    }
    let target_position = optional_position(&mut fields)?;
    let goal_standoff_m = optional_number(&mut fields, STANDOFF_FIELD)?;
    let approach = goal_approach(&mut fields)?;
    fields.insert(
        "prior".to_string(),
        serde_json::json!({"mean": [], "cov": []}),
    );
    let request: OptimizeRequest = from_value(Value::Object(fields))?;
    let (image_field, image_bytes) = &encoded.image;
    let image = decode_image(image_field, image_bytes, state.config().max_image_pixels)?;
    check_box_inside(&target_box, &image)?;
    let target = match (encoded.depth, target_position) {
        (Some(_), Some(_)) => {
            return Err(ApiError::invalid(
                TARGET_FIELD,
                "send either a depth image or a target position, not both",
            ))
        }
        (Some((field, bytes)), None) => TargetInput::Depth(
            decode_depth(field, &bytes, scale, &image)?,
            field.to_string(),
        ),
        (None, Some(p)) => TargetInput::Position(p),
        (None, None) => TargetInput::None,
    };
    if scale.is_some() && !matches!(target, TargetInput::Depth(..)) {
        return Err(ApiError::invalid(
            SCALE_FIELD,
            "applies only with a depth image",
        ));
    }
    if goal_standoff_m.is_some() && matches!(target, TargetInput::None) {
        return Err(ApiError::invalid(
            STANDOFF_FIELD,
            "applies only with a depth image or a target position",
        ));
    }
    Ok(PlanInput {
        image,
        target_box,
        mask_applied,
        target,
        goal_standoff_m,
        request,
        approach,
    })
}

/// A `goal` without a `position` (only with a derived goal): its approach
/// direction, taken out of the request fields.
fn goal_approach(fields: &mut Map<String, Value>) -> Result<Option<GoalApproach>, ApiError> {
    match fields.get("goal") {
        Some(Value::Object(goal)) if !goal.contains_key("position") => {
            #[derive(serde::Deserialize)]
            struct Field {
                goal: GoalApproach,
            }
            let goal = fields.remove("goal").unwrap_or_default();
            let field: Field = from_value(serde_json::json!({ "goal": goal }))?;
            Ok(Some(field.goal))
        }
        _ => Ok(None),
    }
}

/// A 16-bit depth PNG of the image's size.
fn decode_depth(
    field: &str,
    bytes: &[u8],
    scale: Option<f64>,
    image: &DynamicImage,
) -> Result<DepthImage, ApiError> {
    let depth = DepthImage::decode_png(bytes, scale.unwrap_or(DEFAULT_DEPTH_SCALE_M), field)?;
    depth.check_aligned(image.width(), image.height(), field)?;
    Ok(depth)
}

/// An optional finite number field.
fn optional_number(fields: &mut Map<String, Value>, field: &str) -> Result<Option<f64>, ApiError> {
    match fields.remove(field) {
        None | Some(Value::Null) => Ok(None),
        Some(Value::Number(n)) => match n.as_f64() {
            Some(v) if v.is_finite() => Ok(Some(v)),
            _ => Err(ApiError::invalid(field, "must be a finite number")),
        },
        Some(_) => Err(ApiError::invalid(field, "must be a number")),
    }
}

/// The optional `target_position` `[x, y, z]` (m, base frame).
fn optional_position(fields: &mut Map<String, Value>) -> Result<Option<[f64; 3]>, ApiError> {
    let Some(value) = fields.remove(TARGET_FIELD).filter(|v| !v.is_null()) else {
        return Ok(None);
    };
    let numbers: Vec<f64> =
        from_value::<Vec<f64>>(value).map_err(|e| ApiError::invalid(TARGET_FIELD, e.message))?;
    let p: [f64; 3] = numbers.as_slice().try_into().map_err(|_| {
        ApiError::invalid(
            TARGET_FIELD,
            format!("expected 3 numbers [x, y, z], got {}", numbers.len()),
        )
    })?;
    check_target_position(&p)?;
    Ok(Some(p))
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
