//! The one spelling of the robot option, shared by every subcommand that
//! uses a robot: `--robot URDF [--base LINK --tip LINK]`, default the
//! shipped Panda.

use crate::robot::Robot;
use crate::Result;
use std::path::PathBuf;

/// Which robot to load (default: the shipped Panda).
#[derive(Clone, Debug, Default, clap::Args)]
pub struct RobotArgs {
    /// Robot URDF (default: the shipped Panda, models/panda/panda.urdf).
    #[arg(long, alias = "urdf", value_name = "URDF")]
    pub robot: Option<PathBuf>,
    /// Base link of the chain in `--robot`.
    #[arg(
        long,
        alias = "base-link",
        value_name = "LINK",
        default_value = "panda_link0"
    )]
    pub base: String,
    /// Tip link of the chain in `--robot`.
    #[arg(
        long,
        alias = "tip-link",
        value_name = "LINK",
        default_value = "panda_tcp"
    )]
    pub tip: String,
}

impl RobotArgs {
    /// Load the robot the flags name.
    pub fn load(&self) -> Result<Robot> {
        match &self.robot {
            None => Robot::panda(),
            Some(path) => Robot::from_urdf_file(path, &self.base, &self.tip),
        }
    }
}
