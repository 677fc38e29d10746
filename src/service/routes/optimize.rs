//! `POST /v1/optimize`: the optimise request/response of DESIGN.md. The
//! body is read under the body timeout and the deadline; parsing, the
//! service's limits and the solve all run as one job on the blocking pool
//! under the concurrency limit and the deadline counted from arrival.

use crate::optim::{optimize_with, OptimizeRequest, OptimizeResponse, Sharing, SolveControl, Task};
use crate::service::config::ServiceConfig;
use crate::service::error::ApiError;
use crate::service::extract::{
    media_type, parse_json_until, read_body, within_body_time, MediaType,
};
use crate::service::limits::Job;
use crate::service::state::AppState;
use axum::extract::{Request, State};
use axum::Json;

/// `POST /v1/optimize`.
pub async fn optimize(
    State(state): State<AppState>,
    request: Request,
) -> Result<Json<OptimizeResponse>, ApiError> {
    if media_type(request.headers()) != Some(MediaType::Json) {
        return Err(ApiError::unsupported_media_type("application/json"));
    }
    let deadline = state.deadline_of(&request);
    let timeout = state.config().body_read_timeout;
    let bytes = within_body_time(deadline, timeout, read_body(request, &state)).await?;
    let robot = state.robot();
    let config = state.config().clone();
    let response = state
        .limiter()
        .run(deadline, move |job| -> Result<OptimizeResponse, ApiError> {
            let request: OptimizeRequest = parse_json_until(&bytes, &|| job.should_stop())?;
            check_request_limits(&config, &request.task)?;
            Ok(optimize_with(&request, &robot, &solve_control(job))?)
        })
        .await??;
    record_solve(&state, &response);
    Ok(Json(response))
}

/// The solver's view of a limiter job: its deadline and cancel flag, and
/// the jobs sharing the machine's cores (a job runs its loops on one thread
/// while every core has a job).
pub fn solve_control(job: &Job) -> SolveControl {
    SolveControl {
        deadline: Some(job.deadline),
        cancel: Some(job.cancel.clone()),
        sharing: Some(Sharing {
            running: job.running.clone(),
            cores: rayon::current_num_threads(),
        }),
    }
}

/// The service's own request limits (on top of the optimiser's sanity
/// limits): obstacle count, extra samples, trajectory samples → 422.
pub fn check_request_limits(config: &ServiceConfig, task: &Task) -> Result<(), ApiError> {
    let checks = [
        ("obstacles", task.obstacles.len(), config.max_obstacles),
        ("samples", task.samples, config.max_samples),
        (
            "promp.n_samples",
            task.promp.n_samples,
            config.max_trajectory_samples,
        ),
    ];
    for (field, value, limit) in checks {
        if value > limit {
            return Err(ApiError::invalid(
                field,
                format!("at most {limit} allowed by this service, got {value}"),
            ));
        }
    }
    Ok(())
}

/// Count a finished solve in the metrics.
pub fn record_solve(state: &AppState, response: &OptimizeResponse) {
    state.metrics().record_solve(
        response.status.as_str(),
        response.report.iterations,
        response.report.solve_ms / 1e3,
    );
}
