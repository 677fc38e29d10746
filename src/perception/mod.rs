//! What the gripper camera measures, as geometry: the pinhole model and its
//! mount on the gripper ([`camera`]), aligned z-depth images ([`depth`]),
//! the 3-D position of a boxed target from depth ([`target`]), and the
//! point cloud of what the camera sees ([`cloud`]).
//!
//! The synthetic data generator ([`crate::synth`]) renders through the same
//! camera model that planning back-projects through, and a dataset records
//! it, so a depth image and a box mean the same thing in both.

pub mod camera;
pub mod cloud;
pub mod depth;
pub mod target;

pub use camera::{Camera, CameraModel, Intrinsics};

/// What is wrong with an image that did not decode, in a client's words
/// (the decoders' own text carries their internals: `ChunkType { .. }`).
pub fn image_error_words(e: &image::ImageError) -> &'static str {
    use image::ImageError;
    match e {
        ImageError::Decoding(_) | ImageError::Parameter(_) | ImageError::Encoding(_) => {
            "the data is corrupt or truncated"
        }
        ImageError::IoError(_) => "the data ends early (truncated)",
        ImageError::Limits(_) => "it needs more memory than its size allows",
        ImageError::Unsupported(_) => "it uses a feature this decoder does not support",
    }
}
pub use cloud::{depth_cloud, CloudSettings, KeepOut, SensedCloud};
pub use depth::DepthImage;
pub use target::{locate_target, TargetEstimate};
