use super::*;
use proptest::prelude::*;
use std::f64::consts::PI;

/// Hex of each message as PyPI `rosbags` serialises it
/// (scripts/ros2_golden.py, the same values as below).
fn golden(name: &str) -> Vec<u8> {
    let all: serde_json::Value =
        serde_json::from_str(include_str!("../../../fixtures/ros2/golden.json")).unwrap();
    let hex = all[name].as_str().unwrap();
    (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap())
        .collect()
}

fn header(sec: i32, nanosec: u32, frame: &str) -> Header {
    Header {
        stamp: Time { sec, nanosec },
        frame_id: frame.into(),
    }
}

fn laser_scan() -> LaserScan {
    LaserScan {
        header: header(1_700_000_000, 123_456_789, "laser"),
        angle_min: (-PI / 2.0) as f32,
        angle_max: (PI / 2.0) as f32,
        angle_increment: (PI / 360.0) as f32,
        time_increment: (1.0 / 75.0 / 360.0 / 2.0) as f32,
        scan_time: (2.0 / 75.0) as f32,
        range_min: 0.0,
        range_max: 8.183,
        ranges: vec![1.5, f32::INFINITY, 0.25, f32::NAN, 8.0],
        intensities: vec![],
    }
}

fn odometry() -> Odometry {
    let mut covariance = [0.0; 36];
    for (i, c) in covariance.iter_mut().enumerate() {
        *c = 0.01 * i as f64;
    }
    let mut twist_cov = [0.0; 36];
    twist_cov[35] = 1.0;
    Odometry {
        header: header(12, 500_000_000, "odom"),
        child_frame_id: "base_link".into(),
        pose: PoseWithCovariance {
            position: Vector3 {
                x: 1.25,
                y: -2.5,
                z: 0.0,
            },
            orientation: Quaternion::from_yaw(0.75),
            covariance,
        },
        twist: TwistWithCovariance {
            linear: Vector3 {
                x: 0.3,
                y: 0.1,
                z: 0.0,
            },
            angular: Vector3 {
                x: 0.0,
                y: 0.0,
                z: -0.2,
            },
            covariance: twist_cov,
        },
    }
}

fn tf_message() -> TfMessage {
    TfMessage {
        transforms: vec![
            TransformStamped {
                header: header(3, 7, "map"),
                child_frame_id: "odom".into(),
                translation: Vector3 {
                    x: 0.5,
                    y: 0.25,
                    z: 0.0,
                },
                rotation: Quaternion::from_yaw(0.2),
            },
            TransformStamped {
                header: header(3, 8, "odom"),
                child_frame_id: "base_link".into(),
                translation: Vector3 {
                    x: -1.0,
                    y: 2.0,
                    z: 0.0,
                },
                rotation: Quaternion::from_yaw(0.0),
            },
        ],
    }
}

fn pose_with_covariance_stamped() -> PoseWithCovarianceStamped {
    let mut covariance = [0.0; 36];
    for (i, c) in covariance.iter_mut().enumerate() {
        *c = 0.5 - 0.01 * i as f64;
    }
    PoseWithCovarianceStamped {
        header: header(5, 250, "map"),
        pose: PoseWithCovariance {
            position: Vector3 {
                x: 3.5,
                y: -0.125,
                z: 0.0,
            },
            orientation: Quaternion::from_yaw(-1.2),
            covariance,
        },
    }
}

fn occupancy_grid() -> OccupancyGrid {
    OccupancyGrid {
        header: header(9, 1, "map"),
        map_load_time: Time { sec: 8, nanosec: 2 },
        resolution: 0.05,
        width: 3,
        height: 2,
        origin_position: Vector3 {
            x: -1.25,
            y: -0.5,
            z: 0.0,
        },
        origin_orientation: Quaternion::from_yaw(0.0),
        data: vec![0, 100, -1, -1, 0, 100],
    }
}

fn diagnostic_array() -> DiagnosticArray {
    DiagnosticArray {
        header: header(11, 3, ""),
        status: vec![
            DiagnosticStatus {
                level: 1,
                name: "clsmap: sensor".into(),
                message: "SENSOR SILENT".into(),
                hardware_id: "/dev/lms200".into(),
                values: vec![
                    ("scan rate (Hz)".into(), "37.5".into()),
                    ("x".into(), String::new()),
                ],
            },
            DiagnosticStatus {
                level: 0,
                name: "b".into(),
                ..DiagnosticStatus::default()
            },
        ],
    }
}

fn byte_array() -> ByteArray {
    ByteArray {
        data: vec![0x02, 0x80, 0xD6, 0x02, 0xB0],
    }
}

fn twist() -> Twist {
    Twist {
        linear: Vector3 {
            x: 0.25,
            y: -0.125,
            z: 0.0,
        },
        angular: Vector3 {
            x: 0.0,
            y: 0.0,
            z: 0.5,
        },
    }
}

fn marker_array() -> MarkerArray {
    let marker = |ns: &str, id, action, points: &[(f64, f64)], color, width, text: &str| Marker {
        header: header(13, 9, "map"),
        ns: ns.into(),
        id,
        kind: Marker::LINE_LIST,
        action,
        orientation: Quaternion::from_yaw(0.0),
        scale: Vector3 {
            x: width,
            y: 0.0,
            z: 0.0,
        },
        color,
        points: points
            .iter()
            .map(|&(x, y)| Vector3 { x, y, z: 0.0 })
            .collect(),
        text: text.into(),
        ..Marker::default()
    };
    MarkerArray {
        markers: vec![
            marker(
                "walls",
                0,
                Marker::ADD,
                &[(0.5, 1.0), (2.5, -1.25)],
                ColorRgba {
                    r: 0.1,
                    g: 0.1,
                    b: 0.1,
                    a: 1.0,
                },
                0.05,
                "w",
            ),
            marker(
                "frontiers",
                1,
                Marker::DELETE,
                &[],
                ColorRgba {
                    r: 1.0,
                    g: 0.5,
                    b: 0.0,
                    a: 0.75,
                },
                0.0,
                "",
            ),
        ],
    }
}

#[test]
fn messages_match_the_independent_serializer() {
    assert_eq!(twist().to_cdr(), golden("twist"));
    assert_eq!(marker_array().to_cdr(), golden("marker_array"));
    assert_eq!(laser_scan().to_cdr(), golden("laser_scan"));
    assert_eq!(odometry().to_cdr(), golden("odometry"));
    assert_eq!(tf_message().to_cdr(), golden("tf_message"));
    assert_eq!(byte_array().to_cdr(), golden("byte_array"));
    assert_eq!(occupancy_grid().to_cdr(), golden("occupancy_grid"));
    assert_eq!(diagnostic_array().to_cdr(), golden("diagnostic_array"));
    assert_eq!(
        pose_with_covariance_stamped().to_cdr(),
        golden("pose_with_covariance_stamped")
    );
}

#[test]
fn the_independent_serializer_s_bytes_read_back() {
    let scan = LaserScan::from_cdr(&golden("laser_scan")).unwrap();
    assert_eq!(scan.header, laser_scan().header);
    assert_eq!(scan.ranges.len(), 5);
    assert!(scan.ranges[1].is_infinite() && scan.ranges[3].is_nan());
    assert_eq!(Odometry::from_cdr(&golden("odometry")).unwrap(), odometry());
    assert_eq!(
        TfMessage::from_cdr(&golden("tf_message")).unwrap(),
        tf_message()
    );
    assert_eq!(
        ByteArray::from_cdr(&golden("byte_array")).unwrap(),
        byte_array()
    );
    assert_eq!(Twist::from_cdr(&golden("twist")).unwrap(), twist());
    assert_eq!(
        MarkerArray::from_cdr(&golden("marker_array")).unwrap(),
        marker_array()
    );
}

#[test]
fn a_message_of_another_type_is_refused() {
    assert!(LaserScan::from_cdr(&golden("odometry")).is_err());
    assert!(Odometry::from_cdr(&golden("laser_scan")).is_err());
    assert!(TfMessage::from_cdr(&golden("laser_scan")).is_err());
}

#[test]
fn schemas_name_every_type_they_use_once() {
    let s = Odometry::definition();
    assert!(s.starts_with("std_msgs/Header header\nstring child_frame_id\n"));
    for t in [
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3",
    ] {
        assert_eq!(s.matches(&format!("\nMSG: {t}\n")).count(), 1, "{t}\n{s}");
    }
    assert!(TfMessage::definition().contains("MSG: geometry_msgs/Transform\n"));
    assert!(LaserScan::definition().contains("float32[] ranges\n"));
}

#[test]
fn times_round_to_the_nanosecond() {
    let t = Time::from_secs(1_700_000_000.123_456_7).unwrap();
    assert_eq!(t.sec, 1_700_000_000);
    assert!((i64::from(t.nanosec) - 123_456_700).abs() <= 256, "{t:?}");
    assert_eq!(
        Time::from_secs(-0.5).unwrap(),
        Time {
            sec: -1,
            nanosec: 500_000_000
        }
    );
    assert_eq!(Time::from_secs(f64::NAN), None);
    assert_eq!(Time::from_secs(1e12), None);
    assert_eq!(Time { sec: 2, nanosec: 5 }.as_nanos(), 2_000_000_005);
}

proptest! {
    #[test]
    fn yaw_survives_the_quaternion(yaw in -3.1f64..3.1) {
        prop_assert!((Quaternion::from_yaw(yaw).yaw() - yaw).abs() < 1e-12);
    }

    #[test]
    fn damaged_messages_are_errors_not_panics(cut in 0usize..400, flip in 0usize..400) {
        let mut bytes = odometry().to_cdr();
        if let Some(b) = bytes.get_mut(flip) {
            *b ^= 0xff;
        }
        bytes.truncate(cut);
        let _ = Odometry::from_cdr(&bytes);
        let _ = LaserScan::from_cdr(&bytes);
        let _ = TfMessage::from_cdr(&bytes);
        let _ = MarkerArray::from_cdr(&bytes);
    }
}
