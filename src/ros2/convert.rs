//! Messages to the plan's inputs and the plan's answer to messages. Every
//! check names the topic's field (`color.encoding`, `joint_states.name`),
//! so a refused message is logged with what was wrong in it.

use super::msg::{
    CameraInfo, DiagnosticArray, DiagnosticStatus, Header, Image, JointState, JointTrajectory,
    JointTrajectoryPoint, KeyValue, RegionOfInterest, Time,
};
use crate::optim::report::{JointTrajectory as Trajectory, RosDuration};
use crate::perception::{CameraModel, DepthImage, Intrinsics};
use crate::{Error, Result};
use image::{DynamicImage, RgbImage};

/// Metres per unit of a depth image made from a `32FC1` one: 0.1 mm, so
/// 6.55 m of range in 16 bits.
pub const FLOAT_DEPTH_SCALE_M: f64 = 1e-4;

/// Metres per unit of a `16UC1` depth image (REP 118: millimetres).
pub const UINT16_DEPTH_SCALE_M: f64 = 1e-3;

/// The width and height of an image message, checked against the data it
/// carries and `max_pixels`; `bytes_per_pixel` for its encoding.
fn checked_size(msg: &Image, field: &str, bytes_per_pixel: u32, max_pixels: u64) -> Result<()> {
    let (w, h) = (msg.width, msg.height);
    if w == 0 || h == 0 {
        return Err(Error::invalid(
            format!("{field}.width"),
            format!("an empty {w}x{h} image"),
        ));
    }
    if u64::from(w) * u64::from(h) > max_pixels {
        return Err(Error::invalid(
            format!("{field}.width"),
            format!("{w}x{h} is more than the {max_pixels} pixels allowed"),
        ));
    }
    let row = u64::from(w) * u64::from(bytes_per_pixel);
    if u64::from(msg.step) < row {
        return Err(Error::invalid(
            format!("{field}.step"),
            format!(
                "{} bytes per row is short of {w} pixels of {bytes_per_pixel} bytes",
                msg.step
            ),
        ));
    }
    let expected = u64::from(msg.step) * u64::from(h);
    if msg.data.len() as u64 != expected {
        return Err(Error::invalid(
            format!("{field}.data"),
            format!(
                "{} bytes, expected step x height = {expected}",
                msg.data.len()
            ),
        ));
    }
    Ok(())
}

/// Row `y` of an image message: its `width * bytes_per_pixel` bytes.
fn row(msg: &Image, y: u32, bytes_per_pixel: u32) -> &[u8] {
    let start = y as usize * msg.step as usize;
    &msg.data[start..start + (msg.width * bytes_per_pixel) as usize]
}

/// Check a colour image message's encoding (`rgb8` or `bgr8`) and size
/// without reading its pixels; whether it is `bgr8`.
pub fn check_colour(msg: &Image, field: &str, max_pixels: u64) -> Result<bool> {
    let bgr = match msg.encoding.as_str() {
        "rgb8" => false,
        "bgr8" => true,
        other => {
            return Err(Error::invalid(
                format!("{field}.encoding"),
                format!("expected rgb8 or bgr8, got {other:?}"),
            ))
        }
    };
    checked_size(msg, field, 3, max_pixels)?;
    Ok(bgr)
}

/// Check a depth image message's encoding (`16UC1`, `mono16` or `32FC1`)
/// and size without reading its pixels.
pub fn check_depth(msg: &Image, field: &str, max_pixels: u64) -> Result<()> {
    let bytes_per_pixel = match msg.encoding.as_str() {
        "16UC1" | "mono16" => 2,
        "32FC1" => 4,
        other => {
            return Err(Error::invalid(
                format!("{field}.encoding"),
                format!("expected 16UC1 (mm) or 32FC1 (m), got {other:?}"),
            ))
        }
    };
    checked_size(msg, field, bytes_per_pixel, max_pixels)
}

/// A colour image (`rgb8` or `bgr8`) as the network's input.
pub fn colour_image(msg: &Image, field: &str, max_pixels: u64) -> Result<DynamicImage> {
    let bgr = check_colour(msg, field, max_pixels)?;
    let mut pixels = Vec::with_capacity(msg.width as usize * msg.height as usize * 3);
    for y in 0..msg.height {
        let r = row(msg, y, 3);
        if bgr {
            pixels.extend(r.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]));
        } else {
            pixels.extend_from_slice(r);
        }
    }
    RgbImage::from_raw(msg.width, msg.height, pixels)
        .map(DynamicImage::ImageRgb8)
        .ok_or_else(|| Error::invalid(format!("{field}.data"), "not a whole image"))
}

/// An aligned depth image: `16UC1` millimetres (REP 118) or `32FC1`
/// metres. A float pixel that is NaN, infinite, zero or beyond the 16-bit
/// range of [`FLOAT_DEPTH_SCALE_M`] is "no return" (REP 117); a negative
/// one refuses the message.
pub fn depth_image(msg: &Image, field: &str, max_pixels: u64) -> Result<DepthImage> {
    check_depth(msg, field, max_pixels)?;
    let data_field = format!("{field}.data");
    match msg.encoding.as_str() {
        "16UC1" | "mono16" => {
            let mut units = Vec::with_capacity(msg.width as usize * msg.height as usize);
            for y in 0..msg.height {
                units.extend(row(msg, y, 2).chunks_exact(2).map(|b| {
                    let b = [b[0], b[1]];
                    if msg.is_bigendian != 0 {
                        u16::from_be_bytes(b)
                    } else {
                        u16::from_le_bytes(b)
                    }
                }));
            }
            DepthImage::new(
                msg.width,
                msg.height,
                UINT16_DEPTH_SCALE_M,
                units,
                &data_field,
            )
        }
        _ => {
            // 32FC1, as checked.
            let mut metres = Vec::with_capacity(msg.width as usize * msg.height as usize);
            for y in 0..msg.height {
                for b in row(msg, y, 4).chunks_exact(4) {
                    let b = [b[0], b[1], b[2], b[3]];
                    let z = if msg.is_bigendian != 0 {
                        f32::from_be_bytes(b)
                    } else {
                        f32::from_le_bytes(b)
                    };
                    if z.is_finite() && z < 0.0 {
                        return Err(Error::invalid(
                            &data_field,
                            format!("a negative depth ({z} m) at row {y}"),
                        ));
                    }
                    metres.push(f64::from(z));
                }
            }
            DepthImage::from_metres(msg.width, msg.height, FLOAT_DEPTH_SCALE_M, &metres)
                .map_err(|e| e.within(field))
        }
    }
}

/// The camera model of a `CameraInfo`: its intrinsics (`k`) with the
/// mount of `mount` (the model's: where the camera sits on the gripper).
/// Binning and skew are refused (the pinhole model has neither); the
/// distortion is not modelled: [`distortion_norm`] says how much is
/// ignored.
pub fn camera_model(info: &CameraInfo, field: &str, mount: &CameraModel) -> Result<CameraModel> {
    if info.binning_x > 1 || info.binning_y > 1 {
        return Err(Error::invalid(
            format!("{field}.binning_x"),
            format!(
                "binned images ({} x {}) are not supported",
                info.binning_x, info.binning_y
            ),
        ));
    }
    let k = &info.k;
    crate::error::ensure_finite(&format!("{field}.k"), k)?;
    if k[1].abs() > 1e-9 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
        return Err(Error::invalid(
            format!("{field}.k"),
            "expected [fx 0 cx; 0 fy cy; 0 0 1] (no skew)",
        ));
    }
    let camera = CameraModel {
        intrinsics: Intrinsics {
            width: info.width,
            height: info.height,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
        },
        ..*mount
    };
    camera.validate(field)?;
    Ok(camera)
}

/// Largest absolute distortion coefficient of a `CameraInfo` (0 when
/// none): what the pinhole model ignores.
pub fn distortion_norm(info: &CameraInfo) -> f64 {
    info.d.iter().fold(0.0_f64, |m, v| m.max(v.abs()))
}

/// The robot's joint positions from a `JointState`, mapped by name: every
/// one of `joints` must be there, once, with a finite position; names the
/// robot does not have (a gripper's fingers) are left out.
pub fn start_configuration(msg: &JointState, field: &str, joints: &[String]) -> Result<Vec<f64>> {
    if msg.name.len() != msg.position.len() {
        return Err(Error::invalid(
            format!("{field}.position"),
            format!(
                "{} positions for {} names",
                msg.position.len(),
                msg.name.len()
            ),
        ));
    }
    joints
        .iter()
        .map(|joint| {
            let mut found = msg
                .name
                .iter()
                .zip(&msg.position)
                .filter(|(n, _)| *n == joint);
            match (found.next(), found.next()) {
                (Some((_, &q)), None) if q.is_finite() => Ok(q),
                (Some((_, &q)), None) => Err(Error::invalid(
                    format!("{field}.position"),
                    format!("{joint} is {q}"),
                )),
                (Some(_), Some(_)) => Err(Error::invalid(
                    format!("{field}.name"),
                    format!("{joint} appears twice"),
                )),
                (None, _) => Err(Error::invalid(
                    format!("{field}.name"),
                    format!("no {joint} among {:?}", msg.name),
                )),
            }
        })
        .collect()
}

/// A region of interest as the plan's target box `[x1, y1, x2, y2]`
/// (pixels; checked inside the image by the plan request).
pub fn target_box(roi: &RegionOfInterest) -> [f64; 4] {
    let (x, y) = (f64::from(roi.x_offset), f64::from(roi.y_offset));
    [x, y, x + f64::from(roi.width), y + f64::from(roi.height)]
}

/// The plan's trajectory as a `JointTrajectory` message: the same numbers
/// `trajectory_format: ros2` writes in JSON, with a zero stamp ("start
/// when received").
pub fn trajectory_message(trajectory: &Trajectory) -> JointTrajectory {
    JointTrajectory {
        header: Header::default(),
        joint_names: trajectory.joint_names.clone(),
        points: trajectory
            .points
            .iter()
            .map(|p| JointTrajectoryPoint {
                positions: p.positions.clone(),
                velocities: p.velocities.clone(),
                accelerations: p.accelerations.clone(),
                effort: Vec::new(),
                time_from_start: RosDuration::from_seconds(p.time_from_start).into(),
            })
            .collect(),
    }
}

/// A one-status `DiagnosticArray` named `dpmp: plan`.
pub fn diagnostics(
    stamp: Time,
    level: u8,
    message: String,
    values: &[(&str, String)],
) -> DiagnosticArray {
    DiagnosticArray {
        header: Header {
            stamp,
            frame_id: String::new(),
        },
        status: vec![DiagnosticStatus {
            level,
            name: "dpmp: plan".into(),
            message,
            hardware_id: String::new(),
            values: values
                .iter()
                .map(|(k, v)| KeyValue {
                    key: (*k).to_string(),
                    value: v.clone(),
                })
                .collect(),
        }],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(encoding: &str, w: u32, h: u32, bpp: u32, pad: u32) -> Image {
        let step = w * bpp + pad;
        Image {
            height: h,
            width: w,
            encoding: encoding.into(),
            step,
            data: (0..step * h).map(|i| (i % 251) as u8).collect(),
            ..Image::default()
        }
    }

    #[test]
    fn bgr_rows_with_padding_become_the_same_rgb_image() {
        let rgb = image("rgb8", 5, 3, 3, 2);
        let mut bgr = rgb.clone();
        bgr.encoding = "bgr8".into();
        for y in 0..3 {
            for x in 0..5 {
                let i = (y * rgb.step + 3 * x) as usize;
                bgr.data.swap(i, i + 2);
            }
        }
        let a = colour_image(&rgb, "color", 1 << 20).unwrap().to_rgb8();
        let b = colour_image(&bgr, "color", 1 << 20).unwrap().to_rgb8();
        assert_eq!(a, b);
        assert_eq!(
            a.get_pixel(1, 2).0,
            [rgb.data[2 * 17 + 3], rgb.data[38], rgb.data[39]]
        );
    }

    #[test]
    fn bad_images_name_their_field() {
        let mut m = image("rgb8", 4, 4, 3, 0);
        m.data.pop();
        let e = colour_image(&m, "color", 1 << 20).unwrap_err();
        assert_eq!(e.field(), Some("color.data"));
        let m = image("mono8", 4, 4, 1, 0);
        assert_eq!(
            colour_image(&m, "color", 1 << 20).unwrap_err().field(),
            Some("color.encoding")
        );
        let m = image("rgb8", 4, 4, 3, 0);
        assert_eq!(
            colour_image(&m, "color", 15).unwrap_err().field(),
            Some("color.width")
        );
        let mut m = image("16UC1", 4, 4, 2, 0);
        m.step = 6;
        assert_eq!(
            depth_image(&m, "depth", 1 << 20).unwrap_err().field(),
            Some("depth.step")
        );
    }

    #[test]
    fn depth_in_millimetres_and_in_metres_reads_the_same() {
        let (w, h) = (3, 2);
        let mm: [u16; 6] = [0, 250, 1000, 65535, 1, 420];
        let mut u16_msg = image("16UC1", w, h, 2, 0);
        u16_msg.data = mm.iter().flat_map(|v| v.to_le_bytes()).collect();
        let mut be = u16_msg.clone();
        be.is_bigendian = 1;
        be.data = mm.iter().flat_map(|v| v.to_be_bytes()).collect();
        let a = depth_image(&u16_msg, "depth", 100).unwrap();
        let b = depth_image(&be, "depth", 100).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.metres(1, 0), Some(0.25));
        let metres: [f32; 6] = [f32::NAN, 0.25, 1.0, f32::INFINITY, 0.0, 0.42];
        let mut f = image("32FC1", w, h, 4, 0);
        f.data = metres.iter().flat_map(|v| v.to_le_bytes()).collect();
        let c = depth_image(&f, "depth", 100).unwrap();
        for (x, y) in [(1, 0), (2, 0), (2, 1)] {
            let (p, q) = (a.metres(x, y).unwrap(), c.metres(x, y).unwrap());
            assert!((p - q).abs() < 1e-4, "{p} vs {q}");
        }
        // NaN, +inf and 0 are no return.
        for (x, y) in [(0, 0), (0, 1), (1, 1)] {
            assert_eq!(c.metres(x, y), None, "({x}, {y})");
        }
        f.data[4..8].copy_from_slice(&(-0.5f32).to_le_bytes());
        assert_eq!(
            depth_image(&f, "depth", 100).unwrap_err().field(),
            Some("depth.data")
        );
    }

    #[test]
    fn joint_states_map_by_name_and_refuse_what_is_missing_or_nan() {
        let joints: Vec<String> = ["a", "b"].map(String::from).to_vec();
        let msg = JointState {
            name: ["finger", "b", "a"].map(String::from).to_vec(),
            position: vec![0.04, 2.0, 1.0],
            ..JointState::default()
        };
        assert_eq!(
            start_configuration(&msg, "js", &joints).unwrap(),
            vec![1.0, 2.0]
        );
        let mut nan = msg.clone();
        nan.position[2] = f64::NAN;
        assert_eq!(
            start_configuration(&nan, "js", &joints)
                .unwrap_err()
                .field(),
            Some("js.position")
        );
        let mut missing = msg.clone();
        missing.name[1] = "c".into();
        assert_eq!(
            start_configuration(&missing, "js", &joints)
                .unwrap_err()
                .field(),
            Some("js.name")
        );
        let mut twice = msg.clone();
        twice.name[0] = "a".into();
        assert_eq!(
            start_configuration(&twice, "js", &joints)
                .unwrap_err()
                .field(),
            Some("js.name")
        );
        let mut short = msg;
        short.position.pop();
        assert_eq!(
            start_configuration(&short, "js", &joints)
                .unwrap_err()
                .field(),
            Some("js.position")
        );
    }

    #[test]
    fn camera_info_gives_the_intrinsics_and_keeps_the_mount() {
        let mount = CameraModel::default();
        let info = CameraInfo {
            width: 640,
            height: 480,
            k: [600.0, 0.0, 321.5, 0.0, 601.0, 239.5, 0.0, 0.0, 1.0],
            ..CameraInfo::default()
        };
        let c = camera_model(&info, "camera_info", &mount).unwrap();
        assert_eq!(
            (
                c.intrinsics.fx,
                c.intrinsics.fy,
                c.intrinsics.cx,
                c.intrinsics.cy
            ),
            (600.0, 601.0, 321.5, 239.5)
        );
        assert_eq!(
            (c.mount_back_m, c.mount_up_m),
            (mount.mount_back_m, mount.mount_up_m)
        );
        let mut skew = info.clone();
        skew.k[1] = 0.5;
        assert_eq!(
            camera_model(&skew, "camera_info", &mount)
                .unwrap_err()
                .field(),
            Some("camera_info.k")
        );
        let mut nan = info.clone();
        nan.k[0] = f64::NAN;
        assert!(camera_model(&nan, "camera_info", &mount)
            .unwrap_err()
            .field()
            .unwrap()
            .starts_with("camera_info.k"));
        let mut binned = info;
        binned.binning_x = 2;
        assert_eq!(
            camera_model(&binned, "camera_info", &mount)
                .unwrap_err()
                .field(),
            Some("camera_info.binning_x")
        );
    }
}
