//! `POST /v1/moveit/plan`: a MoveIt query (`planning_scene`,
//! `motion_plan_request`) and the optimiser's options in one JSON body;
//! the answer of [`crate::moveit::plan_moveit`], as `dpmp plan-moveit`
//! prints it. Parsing and planning run as one job under the concurrency
//! limit and the deadline counted from arrival (and the request's
//! `allowed_planning_time`).

use super::optimize::{check_request_limits, record_solve, solve_control};
use crate::moveit::{plan_moveit, MoveItPlanOptions, MoveItPlanResponse, MoveItQuery};
use crate::service::error::ApiError;
use crate::service::extract::{
    media_type, object_text, parse_json_until, parse_typed, read_body, within_body_time, Fields,
    MediaType,
};
use crate::service::state::AppState;
use axum::extract::{Request, State};
use axum::Json;

const SCENE_FIELD: &str = "planning_scene";
const REQUEST_FIELD: &str = "motion_plan_request";

/// `POST /v1/moveit/plan`.
pub async fn plan(
    State(state): State<AppState>,
    request: Request,
) -> Result<Json<MoveItPlanResponse>, ApiError> {
    if media_type(request.headers()) != Some(MediaType::Json) {
        return Err(ApiError::unsupported_media_type("application/json"));
    }
    let deadline = state.deadline_of(&request);
    let timeout = state.config().body_read_timeout;
    let bytes = within_body_time(deadline, timeout, read_body(request, &state)).await?;
    let robot = state.robot();
    let config = state.config().clone();
    let answer = state
        .limiter()
        .run(
            deadline,
            move |job| -> Result<MoveItPlanResponse, ApiError> {
                let mut fields: Fields = parse_json_until(&bytes, &|| job.should_stop())?;
                let scene = take(&mut fields, SCENE_FIELD)?;
                let query = take(&mut fields, REQUEST_FIELD)?;
                let options: MoveItPlanOptions = parse_typed(object_text(&fields).as_bytes())?;
                let query = MoveItQuery::read(scene.get(), query.get(), &robot)?;
                check_request_limits(&config, &query.optimize_request(&options)?.task)?;
                Ok(plan_moveit(&query, &options, &robot, &solve_control(job))?)
            },
        )
        .await??;
    record_solve(&state, &answer.result);
    Ok(Json(answer))
}

/// The required member `field`, removed from `fields`.
fn take(
    fields: &mut Fields,
    field: &'static str,
) -> Result<Box<serde_json::value::RawValue>, ApiError> {
    fields
        .remove(field)
        .ok_or_else(|| ApiError::invalid(field, "required"))
}
