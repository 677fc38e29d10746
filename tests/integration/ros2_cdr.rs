//! The ROS 2 message layouts (feature `ros2`), pinned: every message the
//! node reads or writes encodes to the bytes written here by hand from its
//! `.msg` definition, and those bytes decode back to the message.
//!
//! The hand encoding is XCDR1 little endian, what ROS 2's DDS middlewares
//! put after the 4-byte encapsulation header: fields in declaration order,
//! each primitive aligned to its size (8 for `float64`) from the start of
//! the body, strings as a `uint32` length counting a closing NUL then the
//! bytes and the NUL, sequences as a `uint32` count then the elements,
//! fixed arrays (`float64[9]`) without a count. The first tests pin that
//! writer itself against literal bytes.

use byteorder::LittleEndian;
use dpmp::ros2::msg::*;
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::fmt::Debug;

/// An XCDR1 little-endian writer, written from the rules above.
#[derive(Default)]
struct Cdr(Vec<u8>);

impl Cdr {
    fn align(&mut self, n: usize) -> &mut Self {
        while !self.0.len().is_multiple_of(n) {
            self.0.push(0);
        }
        self
    }
    fn u8(&mut self, v: u8) -> &mut Self {
        self.0.push(v);
        self
    }
    fn u16(&mut self, v: u16) -> &mut Self {
        self.align(2).0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4).0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn i32(&mut self, v: i32) -> &mut Self {
        self.align(4).0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8).0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.0.extend_from_slice(s.as_bytes());
        self.0.push(0);
        self
    }
    fn f64s(&mut self, v: &[f64]) -> &mut Self {
        self.u32(v.len() as u32);
        v.iter().for_each(|x| {
            self.f64(*x);
        });
        self
    }
    fn strings(&mut self, v: &[&str]) -> &mut Self {
        self.u32(v.len() as u32);
        v.iter().for_each(|s| {
            self.string(s);
        });
        self
    }
    fn time(&mut self, sec: i32, nanosec: u32) -> &mut Self {
        self.i32(sec).u32(nanosec)
    }
    fn header(&mut self, sec: i32, nanosec: u32, frame: &str) -> &mut Self {
        self.time(sec, nanosec).string(frame)
    }
}

/// `msg` encodes to `bytes` and `bytes` decode to `msg`.
fn pinned<M: Serialize + DeserializeOwned + PartialEq + Debug>(msg: &M, bytes: &[u8]) {
    let ours = cdr_encoding::to_vec::<M, LittleEndian>(msg).unwrap();
    assert_eq!(ours, bytes, "{msg:?} encodes to other bytes");
    let (back, used) = cdr_encoding::from_bytes::<M, LittleEndian>(bytes).unwrap();
    assert_eq!(&back, msg);
    assert_eq!(used, bytes.len());
}

fn header(sec: i32, nanosec: u32, frame: &str) -> Header {
    Header {
        stamp: Time { sec, nanosec },
        frame_id: frame.into(),
    }
}

#[test]
fn the_hand_writer_agrees_with_literal_bytes() {
    // Time{sec: 1, nanosec: 2}; then "ab" (length 3 with the NUL).
    let mut c = Cdr::default();
    c.time(1, 2).string("ab");
    assert_eq!(c.0, [1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, b'a', b'b', 0]);
    // A float64 after a byte is aligned to 8.
    let mut c = Cdr::default();
    c.u8(9).f64(1.0);
    assert_eq!(c.0, [9, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xf0, 0x3f]);
}

#[test]
fn builtin_and_std_messages() {
    pinned(
        &Time {
            sec: -3,
            nanosec: 999_999_999,
        },
        &[0xfd, 0xff, 0xff, 0xff, 0xff, 0xc9, 0x9a, 0x3b],
    );
    pinned(
        &header(7, 500, "base"),
        &Cdr::default().header(7, 500, "base").0,
    );
    // An empty frame id is the length 1 and the NUL.
    pinned(&header(0, 0, ""), &[0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0]);
}

#[test]
fn sensor_msgs_image_and_region_of_interest() {
    let image = Image {
        header: header(12, 34, "camera_color_optical_frame"),
        height: 2,
        width: 1,
        encoding: "rgb8".into(),
        is_bigendian: 0,
        step: 3,
        data: vec![1, 2, 3, 4, 5, 6],
    };
    let mut c = Cdr::default();
    c.header(12, 34, "camera_color_optical_frame")
        .u32(2)
        .u32(1)
        .string("rgb8")
        .u8(0)
        .u32(3)
        .u32(6);
    c.0.extend_from_slice(&[1, 2, 3, 4, 5, 6]);
    pinned(&image, &c.0);

    let roi = RegionOfInterest {
        x_offset: 10,
        y_offset: 20,
        height: 30,
        width: 40,
        do_rectify: true,
    };
    pinned(
        &roi,
        &[10, 0, 0, 0, 20, 0, 0, 0, 30, 0, 0, 0, 40, 0, 0, 0, 1],
    );
}

#[test]
fn sensor_msgs_camera_info() {
    let k = [615.0, 0.0, 320.0, 0.0, 615.0, 240.0, 0.0, 0.0, 1.0];
    let r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let p = [
        615.0, 0.0, 320.0, 0.0, 0.0, 615.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0,
    ];
    let info = CameraInfo {
        header: header(1, 0, "cam"),
        height: 480,
        width: 640,
        distortion_model: "plumb_bob".into(),
        d: vec![0.1, -0.2, 0.0, 0.0, 0.05],
        k,
        r,
        p,
        binning_x: 0,
        binning_y: 1,
        roi: RegionOfInterest {
            x_offset: 1,
            y_offset: 2,
            height: 3,
            width: 4,
            do_rectify: false,
        },
    };
    let mut c = Cdr::default();
    c.header(1, 0, "cam")
        .u32(480)
        .u32(640)
        .string("plumb_bob")
        .f64s(&[0.1, -0.2, 0.0, 0.0, 0.05]);
    for v in k.iter().chain(&r).chain(&p) {
        c.f64(*v);
    }
    c.u32(0).u32(1).u32(1).u32(2).u32(3).u32(4).u8(0);
    pinned(&info, &c.0);
}

#[test]
fn sensor_msgs_joint_state() {
    let js = JointState {
        header: header(5, 6, ""),
        name: vec!["panda_joint1".into(), "panda_joint2".into()],
        position: vec![0.5, -1.25],
        velocity: vec![],
        effort: vec![0.0, 1.0],
    };
    let mut c = Cdr::default();
    c.header(5, 6, "")
        .strings(&["panda_joint1", "panda_joint2"])
        .f64s(&[0.5, -1.25])
        .f64s(&[])
        .f64s(&[0.0, 1.0]);
    pinned(&js, &c.0);
}

#[test]
fn geometry_msgs_transform_stamped() {
    let tf = TransformStamped {
        header: header(9, 0, "panda_link0"),
        child_frame_id: "camera_color_optical_frame".into(),
        transform: Transform {
            translation: Vector3 {
                x: 0.1,
                y: 0.2,
                z: 0.3,
            },
            rotation: Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            },
        },
    };
    let mut c = Cdr::default();
    c.header(9, 0, "panda_link0")
        .string("camera_color_optical_frame");
    for v in [0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0] {
        c.f64(v);
    }
    pinned(&tf, &c.0);
}

#[test]
fn trajectory_msgs_joint_trajectory() {
    let point = |q: f64, t: Time| JointTrajectoryPoint {
        positions: vec![q, q + 1.0],
        velocities: vec![0.0, 0.5],
        accelerations: vec![-1.0, 1.0],
        effort: vec![],
        time_from_start: t,
    };
    let t = JointTrajectory {
        header: header(0, 0, ""),
        joint_names: vec!["a".into(), "b".into()],
        points: vec![
            point(0.25, Time { sec: 0, nanosec: 0 }),
            point(
                1.5,
                Time {
                    sec: 4,
                    nanosec: 10,
                },
            ),
        ],
    };
    let mut c = Cdr::default();
    c.header(0, 0, "").strings(&["a", "b"]).u32(2);
    for (q, sec, ns) in [(0.25, 0, 0), (1.5, 4, 10)] {
        c.f64s(&[q, q + 1.0])
            .f64s(&[0.0, 0.5])
            .f64s(&[-1.0, 1.0])
            .f64s(&[])
            .time(sec, ns);
    }
    pinned(&t, &c.0);
}

#[test]
fn diagnostic_msgs_diagnostic_array() {
    let d = DiagnosticArray {
        header: header(3, 4, ""),
        status: vec![DiagnosticStatus {
            level: DiagnosticStatus::WARN,
            name: "dpmp: plan".into(),
            message: "max_iterations".into(),
            hardware_id: String::new(),
            values: vec![KeyValue {
                key: "plan_ms".into(),
                value: "12.5".into(),
            }],
        }],
    };
    let mut c = Cdr::default();
    c.header(3, 4, "")
        .u32(1)
        .u8(1)
        .string("dpmp: plan")
        .string("max_iterations")
        .string("")
        .u32(1)
        .string("plan_ms")
        .string("12.5");
    pinned(&d, &c.0);
}

#[test]
fn truncated_bytes_are_an_error_not_a_panic() {
    let image = Image {
        encoding: "rgb8".into(),
        data: vec![1; 12],
        ..Image::default()
    };
    let bytes = cdr_encoding::to_vec::<Image, LittleEndian>(&image).unwrap();
    for cut in [0, 3, 9, bytes.len() - 1] {
        assert!(
            cdr_encoding::from_bytes::<Image, LittleEndian>(&bytes[..cut]).is_err(),
            "cut {cut}"
        );
    }
}

#[test]
fn control_msgs_follow_joint_trajectory_goal_and_result() {
    let goal = FollowJointTrajectoryGoal {
        trajectory: JointTrajectory {
            header: header(0, 0, ""),
            joint_names: vec!["j".into()],
            points: vec![JointTrajectoryPoint {
                positions: vec![0.5],
                velocities: vec![],
                accelerations: vec![],
                effort: vec![],
                time_from_start: Time { sec: 4, nanosec: 0 },
            }],
        },
        multi_dof_trajectory: MultiDofJointTrajectory::default(),
        path_tolerance: vec![JointTolerance {
            name: "j".into(),
            position: 0.1,
            velocity: 0.2,
            acceleration: 0.3,
        }],
        component_path_tolerance: vec![JointComponentTolerance {
            joint_name: "k".into(),
            component: 3,
            position: 1.0,
            velocity: 2.0,
            acceleration: 3.0,
        }],
        goal_tolerance: vec![],
        component_goal_tolerance: vec![],
        goal_time_tolerance: Time { sec: 1, nanosec: 5 },
    };
    let mut c = Cdr::default();
    // trajectory
    c.header(0, 0, "").strings(&["j"]).u32(1);
    c.f64s(&[0.5]).f64s(&[]).f64s(&[]).f64s(&[]).time(4, 0);
    // multi_dof_trajectory: header, no names, no points
    c.header(0, 0, "").strings(&[]).u32(0);
    // path_tolerance
    c.u32(1).string("j").f64(0.1).f64(0.2).f64(0.3);
    // component_path_tolerance: the uint16 aligned to 2, then float64s to 8
    c.u32(1).string("k").u16(3).f64(1.0).f64(2.0).f64(3.0);
    // goal_tolerance, component_goal_tolerance, goal_time_tolerance
    c.u32(0).u32(0).time(1, 5);
    pinned(&goal, &c.0);

    let result = FollowJointTrajectoryResult {
        error_code: -4,
        error_string: "path".into(),
    };
    let mut c = Cdr::default();
    c.i32(-4).string("path");
    pinned(&result, &c.0);
}
