//! `POST /v1/plan`: image (+ aligned depth) + target box → network prior
//! → (pre-grasp goal) → optimiser; the pipeline is [`crate::plan`].
//!
//! Two encodings of the same request:
//! - `application/json`: `{"image_base64": "...", "target_box": [x1, y1, x2, y2],
//!   "mask_applied": false, "depth_base64": "..." (optional 16-bit PNG),
//!   "depth_scale_m": 0.001, "target_position": [x, y, z] (optional, instead
//!   of depth), "goal_standoff_m": 0.1, "world": "depth" (optional: the
//!   depth image's cloud as an obstacle), ...scene and constraint fields of
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
use crate::optim::{GoalApproach, Task};
use crate::perception::depth::check_scale;
use crate::perception::depth::{DepthImage, DEFAULT_DEPTH_SCALE_M};
use crate::perception::CameraModel;
use crate::plan::{
    predict_and_optimize, PlanFields, PlanParts, PlanRequest, PlanResponse, WorldSource,
};
use crate::service::config::ServiceConfig;
use crate::service::error::ApiError;
use crate::service::extract::{
    media_type, object_text, parse_json_until, parse_member, parse_typed, read_body,
    within_body_time, Fields, MediaType,
};
use crate::service::image::{
    decode_base64, decode_image_within, read_header, DecodeBudget, Reservation,
};
use crate::service::state::AppState;
use axum::body::Bytes;
use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::StatusCode;
use axum::Json;
use image::DynamicImage;
use serde_json::value::RawValue;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

/// Fields of a plan request that are not optimiser fields.
const IMAGE_FIELD: &str = "image_base64";
const BOX_FIELD: &str = "target_box";
const MASK_FIELD: &str = "mask_applied";
const DEPTH_FIELD: &str = "depth_base64";
/// The multipart part holding the colour image.
const MULTIPART_IMAGE: &str = "image";
const DEPTH_PART: &str = "depth";
const SCALE_FIELD: &str = "depth_scale_m";
const TARGET_FIELD: &str = "target_position";
const STANDOFF_FIELD: &str = "goal_standoff_m";
const CAMERA_FIELD: &str = "camera";
const WORLD_FIELD: &str = "world";

/// A request as received, nothing parsed or decoded yet: that is CPU work
/// and runs in the request's job.
enum Received {
    /// The JSON body.
    Json(Bytes),
    /// The multipart parts.
    Multipart {
        image: Option<Bytes>,
        depth: Option<Bytes>,
        request: Option<Bytes>,
    },
}

/// Encoded inputs of one request: (field naming it in errors, bytes).
struct Encoded {
    image: (&'static str, Vec<u8>),
    depth: Option<(&'static str, Vec<u8>)>,
}

/// What a job needs to turn a received request into a [`PlanRequest`].
struct Decoding {
    config: ServiceConfig,
    budget: Arc<DecodeBudget>,
    deadline: Instant,
}

/// `POST /v1/plan`.
pub async fn plan(
    State(state): State<AppState>,
    request: Request,
) -> Result<Json<PlanResponse>, ApiError> {
    let deadline = state.deadline_of(&request);
    let timeout = state.config().body_read_timeout;
    let received = match media_type(request.headers()) {
        Some(MediaType::Json) => {
            Received::Json(within_body_time(deadline, timeout, read_body(request, &state)).await?)
        }
        Some(MediaType::Multipart) => {
            within_body_time(deadline, timeout, read_multipart(&state, request)).await?
        }
        None => {
            return Err(ApiError::unsupported_media_type(
                "application/json or multipart/form-data",
            ))
        }
    };
    // Without a model the request is still parsed first, so that a client's
    // mistakes are named before the server's missing piece.
    let model = state.model();
    let robot = state.robot();
    let decoding = Decoding {
        config: state.config().clone(),
        budget: state.decode_budget(),
        deadline,
    };
    let response = state
        .limiter()
        .run(deadline, move |job| -> Result<PlanResponse, ApiError> {
            let (input, _held) = received.into_input(&decoding, &|| job.should_stop())?;
            check_request_limits(&decoding.config, input.task())?;
            let model = model.ok_or_else(ApiError::model_unavailable)?;
            Ok(predict_and_optimize(
                &model,
                &robot,
                input,
                &solve_control(job),
            )?)
        })
        .await??;
    record_solve(&state, &response.result);
    Ok(Json(response))
}

/// Collect the parts of a multipart request (bytes only).
async fn read_multipart(state: &AppState, request: Request) -> Result<Received, ApiError> {
    let mut multipart = Multipart::from_request(request, state)
        .await
        .map_err(|e| multipart_error(e.status(), e.body_text()))?;
    let (mut image, mut depth, mut fields) = (None, None, None);
    while let Some(part) = multipart
        .next_field()
        .await
        .map_err(|e| multipart_error(e.status(), e.body_text()))?
    {
        let name = part.name().unwrap_or_default().to_string();
        let slot = match name.as_str() {
            MULTIPART_IMAGE => &mut image,
            DEPTH_PART => &mut depth,
            "request" => &mut fields,
            other => {
                return Err(malformed_multipart(&format!(
                    "unknown part `{other}`: expected `image`, `request` and optionally `depth`"
                )))
            }
        };
        if slot.is_some() {
            return Err(malformed_multipart(&format!(
                "the part `{name}` appears twice"
            )));
        }
        let bytes = part
            .bytes()
            .await
            .map_err(|e| multipart_error(e.status(), e.body_text()))?;
        *slot = Some(bytes);
    }
    Ok(Received::Multipart {
        image,
        depth,
        request: fields,
    })
}

impl Received {
    /// Parse and decode (in the request's job): the [`PlanRequest`] and the
    /// room its decoded images hold in the budget.
    fn into_input(
        self,
        decoding: &Decoding,
        stop: &dyn Fn() -> bool,
    ) -> Result<(PlanRequest, Vec<Reservation>), ApiError> {
        let (encoded, fields) = match self {
            Received::Json(bytes) => {
                let mut fields: Fields = parse_json_until(&bytes, stop)?;
                let image = (
                    IMAGE_FIELD,
                    take_base64(&mut fields, IMAGE_FIELD)?.ok_or_else(|| {
                        ApiError::invalid(IMAGE_FIELD, "missing: the PNG or JPEG image as base64")
                    })?,
                );
                let depth = take_base64(&mut fields, DEPTH_FIELD)?.map(|d| (DEPTH_FIELD, d));
                (Encoded { image, depth }, fields)
            }
            Received::Multipart {
                image,
                depth,
                request,
            } => {
                let image = image.ok_or_else(|| malformed_multipart("missing the part `image`"))?;
                let request =
                    request.ok_or_else(|| malformed_multipart("missing the part `request`"))?;
                let fields: Fields = parse_json_until(&request, stop)?;
                for (field, part) in [(IMAGE_FIELD, MULTIPART_IMAGE), (DEPTH_FIELD, DEPTH_PART)] {
                    if fields.contains_key(field) {
                        return Err(ApiError::invalid(
                            field,
                            format!("send it either as the `{part}` part or as base64, not both"),
                        ));
                    }
                }
                let encoded = Encoded {
                    image: (MULTIPART_IMAGE, image.to_vec()),
                    depth: depth.map(|d| (DEPTH_PART, d.to_vec())),
                };
                (encoded, fields)
            }
        };
        finish_input(decoding, encoded, fields)
    }
}

/// A base64 string field taken out of `fields` and decoded (`None` when
/// absent or null).
fn take_base64(fields: &mut Fields, field: &str) -> Result<Option<Vec<u8>>, ApiError> {
    let Some(raw) = fields.remove(field) else {
        return Ok(None);
    };
    match serde_json::from_str::<Option<String>>(raw.get()) {
        Ok(None) => Ok(None),
        Ok(Some(text)) => decode_base64(field, &text).map(Some),
        Err(_) => Err(ApiError::invalid(field, "must be a base64 string")),
    }
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

/// Take the plan fields out of the body, parse the rest as the optimiser's
/// [`Task`] (the prior is the prediction), decode the image and the depth
/// within the decode budget, and validate the whole as a [`PlanRequest`].
fn finish_input(
    decoding: &Decoding,
    encoded: Encoded,
    mut fields: Fields,
) -> Result<(PlanRequest, Vec<Reservation>), ApiError> {
    if fields.contains_key("prior") {
        return Err(ApiError::invalid(
            "prior",
            "/v1/plan predicts the prior from the image; send a prior to /v1/optimize instead",
        ));
    }
    let target_box = parse_box(fields.remove(BOX_FIELD))?;
    let mask_applied = match fields.remove(MASK_FIELD) {
        None => false,
        Some(raw) => serde_json::from_str::<bool>(raw.get())
            .map_err(|_| ApiError::invalid(MASK_FIELD, "must be true or false"))?,
    };
    let depth_scale_m = optional_number(&mut fields, SCALE_FIELD)?;
    if let Some(scale) = depth_scale_m {
        check_scale(scale, SCALE_FIELD)?;
    }
    let target_position = optional_position(&mut fields)?;
    let goal_standoff_m = optional_number(&mut fields, STANDOFF_FIELD)?;
    let approach = goal_approach(&mut fields)?;
    let camera = take_camera(&mut fields)?;
    let world = take_world(&mut fields)?;
    let task: Task = parse_typed(object_text(&fields).as_bytes())?;
    let (image_field, image_bytes) = &encoded.image;
    let max_pixels = decoding.config.max_image_pixels;
    let (image, image_held) = decode_image_within(
        image_field,
        image_bytes,
        max_pixels,
        &decoding.budget,
        decoding.deadline,
    )?;
    let mut held = vec![image_held];
    let depth = match encoded.depth {
        Some((field, bytes)) => {
            let (depth, depth_held) = decode_depth(decoding, field, &bytes, depth_scale_m, &image)?;
            held.push(depth_held);
            Some(depth)
        }
        None => None,
    };
    let names = if *image_field == MULTIPART_IMAGE {
        PlanFields::multipart()
    } else {
        PlanFields::json()
    };
    let parts = PlanParts {
        image,
        target_box,
        mask_applied,
        depth,
        depth_scale_m,
        target_position,
        goal_standoff_m,
        approach,
        camera,
        camera_pose: None,
        world,
        task,
    };
    Ok((PlanRequest::new(parts, &names)?, held))
}

/// The optional `camera` (intrinsics and mount), parsed (its values are
/// checked by [`PlanRequest::new`]).
fn take_camera(fields: &mut Fields) -> Result<Option<CameraModel>, ApiError> {
    let Some(raw) = fields.remove(CAMERA_FIELD) else {
        return Ok(None);
    };
    parse_member(CAMERA_FIELD, &raw).map(Some)
}

/// The optional `world` (`"none"` or `"depth"`).
fn take_world(fields: &mut Fields) -> Result<WorldSource, ApiError> {
    let Some(raw) = fields.remove(WORLD_FIELD) else {
        return Ok(WorldSource::None);
    };
    match serde_json::from_str::<String>(raw.get()) {
        Ok(w) => Ok(WorldSource::parse(&w, WORLD_FIELD)?),
        Err(_) => Err(ApiError::invalid(
            WORLD_FIELD,
            "must be the string \"none\" or \"depth\"",
        )),
    }
}

/// A `goal` without a `position` (only with a derived goal): its approach
/// direction, taken out of the request fields.
fn goal_approach(fields: &mut Fields) -> Result<Option<GoalApproach>, ApiError> {
    let Some(raw) = fields.get("goal") else {
        return Ok(None);
    };
    let has_position = match serde_json::from_str::<BTreeMap<String, Box<RawValue>>>(raw.get()) {
        Ok(members) => members.contains_key("position"),
        // Not an object: the optimiser's own parse names what is wrong.
        Err(_) => return Ok(None),
    };
    if has_position {
        return Ok(None);
    }
    let raw = fields
        .remove("goal")
        .ok_or_else(|| ApiError::invalid("goal", "missing"))?;
    parse_member("goal", &raw).map(Some)
}

/// A 16-bit depth PNG of the image's size: the size checked from its header
/// before decoding, the decoded bytes held in the budget.
fn decode_depth(
    decoding: &Decoding,
    field: &str,
    bytes: &[u8],
    scale: Option<f64>,
    image: &DynamicImage,
) -> Result<(DepthImage, Reservation), ApiError> {
    let header = read_header(field, bytes, decoding.config.max_image_pixels)?;
    if (header.width, header.height) != (image.width(), image.height()) {
        return Err(ApiError::invalid(
            field,
            format!(
                "the depth image is {}x{}, the colour image {}x{}: they must be aligned",
                header.width,
                header.height,
                image.width(),
                image.height()
            ),
        ));
    }
    let held = decoding
        .budget
        .reserve(field, 2 * header.decoded_bytes, decoding.deadline)?;
    let depth = DepthImage::decode_png(bytes, scale.unwrap_or(DEFAULT_DEPTH_SCALE_M), field)?;
    depth.check_aligned(image.width(), image.height(), field)?;
    Ok((depth, held))
}

/// An optional finite number field.
fn optional_number(fields: &mut Fields, field: &str) -> Result<Option<f64>, ApiError> {
    let Some(raw) = fields.remove(field) else {
        return Ok(None);
    };
    match serde_json::from_str::<Option<f64>>(raw.get()) {
        Ok(Some(v)) if !v.is_finite() => Err(ApiError::invalid(field, "must be a finite number")),
        Ok(v) => Ok(v),
        Err(_) => Err(ApiError::invalid(field, "must be a number")),
    }
}

/// A short list of numbers (at most 16: a box, a position).
#[derive(serde::Deserialize)]
struct Numbers(#[serde(deserialize_with = "crate::strict_json::vec_at_most::<_, _, 16>")] Vec<f64>);

/// The numbers of `raw`, errors naming `field`.
fn numbers(field: &str, raw: &RawValue) -> Result<Vec<f64>, ApiError> {
    serde_json::from_str::<Numbers>(raw.get())
        .map(|n| n.0)
        .map_err(|e| ApiError::invalid(field, crate::strict_json::message_of(&e)))
}

/// The optional `target_position` `[x, y, z]` (m, base frame).
fn optional_position(fields: &mut Fields) -> Result<Option<[f64; 3]>, ApiError> {
    let Some(raw) = fields.remove(TARGET_FIELD).filter(|v| v.get() != "null") else {
        return Ok(None);
    };
    let numbers = numbers(TARGET_FIELD, &raw)?;
    let p: [f64; 3] = numbers.as_slice().try_into().map_err(|_| {
        ApiError::invalid(
            TARGET_FIELD,
            format!("expected 3 numbers [x, y, z], got {}", numbers.len()),
        )
    })?;
    Ok(Some(p))
}

fn parse_box(raw: Option<Box<RawValue>>) -> Result<[f64; 4], ApiError> {
    let raw = raw.ok_or_else(|| {
        ApiError::invalid(
            BOX_FIELD,
            "missing: the target box [x1, y1, x2, y2] in pixels",
        )
    })?;
    let numbers = numbers(BOX_FIELD, &raw)?;
    let b: [f64; 4] = numbers.as_slice().try_into().map_err(|_| {
        ApiError::invalid(
            BOX_FIELD,
            format!("expected 4 numbers [x1, y1, x2, y2], got {}", numbers.len()),
        )
    })?;
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(text: &str) -> Option<Box<RawValue>> {
        Some(RawValue::from_string(text.to_string()).unwrap())
    }

    #[test]
    fn boxes_are_validated_naming_the_field() {
        assert_eq!(
            parse_box(raw("[1, 2, 3, 4]")).unwrap(),
            [1.0, 2.0, 3.0, 4.0]
        );
        let long = format!("[{}0]", "0,".repeat(100_000));
        for bad in ["[1, 2, 3]", r#"[1, 2, 3, "4"]"#, r#""box""#, &long] {
            let e = parse_box(raw(bad)).unwrap_err();
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
    }
}
