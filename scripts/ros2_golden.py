#!/usr/bin/env python3
"""Golden CDR bytes of the ROS 2 messages clsmap writes, produced by an
independent serializer (PyPI `rosbags`, its ROS 2 Humble type store).

    python3 scripts/ros2_golden.py fixtures/ros2/golden.json

The values are chosen to exercise alignment (odd-length strings before
8-byte fields), invalid ranges (inf, NaN) and empty sequences. The Rust
test `ros2::msg::tests::messages_match_the_independent_serializer` builds
the same messages and compares its bytes with these.
"""
import json
import math
import sys

from rosbags.typesys import Stores, get_typestore

store = get_typestore(Stores.ROS2_HUMBLE)
T = store.types
Time = T["builtin_interfaces/msg/Time"]
Header = T["std_msgs/msg/Header"]
Vector3 = T["geometry_msgs/msg/Vector3"]
Point = T["geometry_msgs/msg/Point"]
Quaternion = T["geometry_msgs/msg/Quaternion"]


def header(sec, nanosec, frame):
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame)


def f32(values):
    import numpy as np

    return np.array(values, dtype=np.float32)


def f64(values):
    import numpy as np

    return np.array(values, dtype=np.float64)


def u8(values):
    import numpy as np

    return np.array(values, dtype=np.uint8)


cases = []

scan = T["sensor_msgs/msg/LaserScan"](
    header=header(1_700_000_000, 123_456_789, "laser"),
    angle_min=-math.pi / 2,
    angle_max=math.pi / 2,
    angle_increment=math.pi / 360,
    time_increment=1.0 / 75 / 360 / 2,
    scan_time=2.0 / 75,
    range_min=0.0,
    range_max=8.183,
    ranges=f32([1.5, math.inf, 0.25, math.nan, 8.0]),
    intensities=f32([]),
)
cases.append(("laser_scan", scan, "sensor_msgs/msg/LaserScan"))

Pwc = T["geometry_msgs/msg/PoseWithCovariance"]
Pose = T["geometry_msgs/msg/Pose"]
Twc = T["geometry_msgs/msg/TwistWithCovariance"]
Twist = T["geometry_msgs/msg/Twist"]
yaw = 0.75
odom = T["nav_msgs/msg/Odometry"](
    header=header(12, 500_000_000, "odom"),
    child_frame_id="base_link",
    pose=Pwc(
        pose=Pose(
            position=Point(x=1.25, y=-2.5, z=0.0),
            orientation=Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)),
        ),
        covariance=f64([0.01 * i for i in range(36)]),
    ),
    twist=Twc(
        twist=Twist(linear=Vector3(x=0.3, y=0.1, z=0.0), angular=Vector3(x=0.0, y=0.0, z=-0.2)),
        covariance=f64([0.0] * 35 + [1.0]),
    ),
)
cases.append(("odometry", odom, "nav_msgs/msg/Odometry"))

Ts = T["geometry_msgs/msg/TransformStamped"]
Tf = T["geometry_msgs/msg/Transform"]
tf = T["tf2_msgs/msg/TFMessage"](
    transforms=[
        Ts(
            header=header(3, 7, "map"),
            child_frame_id="odom",
            transform=Tf(
                translation=Vector3(x=0.5, y=0.25, z=0.0),
                rotation=Quaternion(x=0.0, y=0.0, z=math.sin(0.1), w=math.cos(0.1)),
            ),
        ),
        Ts(
            header=header(3, 8, "odom"),
            child_frame_id="base_link",
            transform=Tf(
                translation=Vector3(x=-1.0, y=2.0, z=0.0),
                rotation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        ),
    ]
)
cases.append(("tf_message", tf, "tf2_msgs/msg/TFMessage"))

Pwcs = T["geometry_msgs/msg/PoseWithCovarianceStamped"]
pose = Pwcs(
    header=header(5, 250, "map"),
    pose=Pwc(
        pose=Pose(
            position=Point(x=3.5, y=-0.125, z=0.0),
            orientation=Quaternion(x=0.0, y=0.0, z=math.sin(-0.6), w=math.cos(-0.6)),
        ),
        covariance=f64([0.5 - 0.01 * i for i in range(36)]),
    ),
)
cases.append(("pose_with_covariance_stamped", pose, "geometry_msgs/msg/PoseWithCovarianceStamped"))

Meta = T["nav_msgs/msg/MapMetaData"]
grid = T["nav_msgs/msg/OccupancyGrid"](
    header=header(9, 1, "map"),
    info=Meta(
        map_load_time=Time(sec=8, nanosec=2),
        resolution=0.05,
        width=3,
        height=2,
        origin=Pose(
            position=Point(x=-1.25, y=-0.5, z=0.0),
            orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
        ),
    ),
    data=__import__("numpy").array([0, 100, -1, -1, 0, 100], dtype=__import__("numpy").int8),
)
cases.append(("occupancy_grid", grid, "nav_msgs/msg/OccupancyGrid"))

KeyValue = T["diagnostic_msgs/msg/KeyValue"]
Status = T["diagnostic_msgs/msg/DiagnosticStatus"]
diag = T["diagnostic_msgs/msg/DiagnosticArray"](
    header=header(11, 3, ""),
    status=[
        Status(
            level=1,
            name="clsmap: sensor",
            message="SENSOR SILENT",
            hardware_id="/dev/lms200",
            values=[KeyValue(key="scan rate (Hz)", value="37.5"), KeyValue(key="x", value="")],
        ),
        Status(level=0, name="b", message="", hardware_id="", values=[]),
    ],
)
cases.append(("diagnostic_array", diag, "diagnostic_msgs/msg/DiagnosticArray"))

Layout = T["std_msgs/msg/MultiArrayLayout"]
raw = T["std_msgs/msg/UInt8MultiArray"](
    layout=Layout(dim=[], data_offset=0), data=u8([0x02, 0x80, 0xD6, 0x02, 0xB0])
)
cases.append(("byte_array", raw, "std_msgs/msg/UInt8MultiArray"))

cmd = Twist(linear=Vector3(x=0.25, y=-0.125, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.5))
cases.append(("twist", cmd, "geometry_msgs/msg/Twist"))

Color = T["std_msgs/msg/ColorRGBA"]
Duration = T["builtin_interfaces/msg/Duration"]
Marker = T["visualization_msgs/msg/Marker"]
Image = T["sensor_msgs/msg/CompressedImage"]
MeshFile = T["visualization_msgs/msg/MeshFile"]


def marker(ns, mid, kind, action, points, color, width, text):
    return Marker(
        header=header(13, 9, "map"),
        ns=ns,
        id=mid,
        type=kind,
        action=action,
        pose=Pose(
            position=Point(x=0.0, y=0.0, z=0.0),
            orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
        ),
        scale=Vector3(x=width, y=0.0, z=0.0),
        color=Color(r=color[0], g=color[1], b=color[2], a=color[3]),
        lifetime=Duration(sec=0, nanosec=0),
        frame_locked=False,
        points=[Point(x=x, y=y, z=0.0) for x, y in points],
        colors=[],
        texture_resource="",
        texture=Image(header=header(0, 0, ""), format="", data=u8([])),
        uv_coordinates=[],
        text=text,
        mesh_resource="",
        mesh_file=MeshFile(filename="", data=u8([])),
        mesh_use_embedded_materials=False,
    )


markers = T["visualization_msgs/msg/MarkerArray"](
    markers=[
        marker("walls", 0, 5, 0, [(0.5, 1.0), (2.5, -1.25)], (0.1, 0.1, 0.1, 1.0), 0.05, "w"),
        marker("frontiers", 1, 5, 2, [], (1.0, 0.5, 0.0, 0.75), 0.0, ""),
    ]
)
cases.append(("marker_array", markers, "visualization_msgs/msg/MarkerArray"))

out = {name: store.serialize_cdr(msg, typename).hex() for name, msg, typename in cases}
with open(sys.argv[1], "w") as f:
    json.dump(out, f, indent=1, sort_keys=True)
    f.write("\n")
