//! The controller's `control_msgs/action/FollowJointTrajectory` action:
//! the client the node sends `optimal` trajectories to, and what becomes
//! of each goal (logged; the plan loop never waits on it).

use super::config::Reliability;
use super::dds::{dds, qos};
use super::msg::{
    FollowJointTrajectoryFeedback, FollowJointTrajectoryGoal, FollowJointTrajectoryResult,
    JointTrajectory,
};
use super::names::resolved_topic;
use crate::Result;
use ros2_client::action::ActionClientQosPolicies;
use ros2_client::qos::{Durability, History};
use ros2_client::{ActionClient, ActionTypeName, Node, ServiceMapping};
use std::sync::Arc;
use std::time::Duration;

/// The controller's `FollowJointTrajectory` action.
pub type Controller = ActionClient<
    FollowJointTrajectoryGoal,
    FollowJointTrajectoryResult,
    FollowJointTrajectoryFeedback,
>;

/// How long the controller has to accept or reject a goal.
const GOAL_RESPONSE_TIMEOUT: Duration = Duration::from_secs(5);

/// The action client for `name`, with ROS 2's default action QoS
/// (reliable services and feedback, a transient-local status topic).
pub fn controller(node: &mut Node, name: &str) -> Result<Controller> {
    let services = qos(Reliability::Reliable, 10);
    let status = services
        .clone()
        .history(History::KeepLast { depth: 1 })
        .durability(Durability::TransientLocal);
    let qos = ActionClientQosPolicies {
        goal_service: services.clone(),
        result_service: services.clone(),
        cancel_service: services.clone(),
        feedback_subscription: services,
        status_subscription: status,
    };
    node.create_action_client(
        ServiceMapping::Enhanced,
        &resolved_topic(node.namespace(), name, "controller.action")?,
        &ActionTypeName::new("control_msgs", "FollowJointTrajectory"),
        qos,
    )
    .map_err(|e| dds(&format!("action client {name}"), e))
}

/// Send `trajectory` to the controller and log what becomes of it: the
/// goal's acceptance, then its result (within the motion's duration and a
/// minute).
pub async fn follow(controller: Arc<Controller>, trajectory: JointTrajectory) {
    let duration = trajectory
        .points
        .last()
        .map_or(0.0, |p| p.time_from_start.seconds());
    let goal = FollowJointTrajectoryGoal {
        trajectory,
        ..FollowJointTrajectoryGoal::default()
    };
    let sent = tokio::time::timeout(GOAL_RESPONSE_TIMEOUT, controller.async_send_goal(goal)).await;
    let goal_id = match sent {
        Ok(Ok((id, response))) if response.accepted => id,
        Ok(Ok(_)) => return tracing::warn!("the controller rejected the trajectory"),
        Ok(Err(e)) => return tracing::error!(error = ?e, "the goal could not be sent"),
        Err(_) => return tracing::error!("no answer from the controller within 5 s"),
    };
    tracing::info!("the controller accepted the trajectory");
    let wait = Duration::from_secs_f64(duration + 60.0);
    match tokio::time::timeout(wait, controller.async_request_result(goal_id)).await {
        Ok(Ok((status, result))) => tracing::info!(
            ?status,
            error_code = result.error_code,
            error = %result.error_string,
            "the controller finished the trajectory"
        ),
        Ok(Err(e)) => tracing::error!(error = ?e, "no result from the controller"),
        Err(_) => tracing::error!("no result from the controller in time"),
    }
}
