#!/usr/bin/env python3
"""A ROS 2 subscriber on an independent DDS stack (PyPI `cyclonedds`, no
ROS installation): subscribes to /scan, /pose, /tf, /tf_static, /map and
/diagnostics as RViz would, with the ROS 2 type names and the message
layouts written here from the ROS 2 definitions, waits (bounded) for samples on each, and prints one
JSON report. /tf_static and /map are read transient-local, so a
subscriber that joins after they were sent still gets them.

    python3 scripts/ros2_subscriber.py --domain 0 --timeout 60 [--namespace /robot1]

With --cmd-vel V it then drives the robot: Twist messages on /cmd_vel at
10 Hz for --drive seconds, and reports how far the pose moved.

Exits 1 if a topic saw nothing before the timeout.
"""
import argparse
import json
import math
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float32, float64, int8, int32, sequence, uint8, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class LaserScan(IdlStruct, typename="sensor_msgs::msg::dds_::LaserScan_"):
    header: Header
    angle_min: float32
    angle_max: float32
    angle_increment: float32
    time_increment: float32
    scan_time: float32
    range_min: float32
    range_max: float32
    ranges: sequence[float32]
    intensities: sequence[float32]


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: array[float64, 36]


@dataclass
class PoseWithCovarianceStamped(
    IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
):
    header: Header
    pose: PoseWithCovariance


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class MapMetaData(IdlStruct, typename="nav_msgs::msg::dds_::MapMetaData_"):
    map_load_time: Time
    resolution: float32
    width: uint32
    height: uint32
    origin: Pose


@dataclass
class OccupancyGrid(IdlStruct, typename="nav_msgs::msg::dds_::OccupancyGrid_"):
    header: Header
    info: MapMetaData
    data: sequence[int8]


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str
    value: str


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8
    name: str
    message: str
    hardware_id: str
    values: sequence[KeyValue]


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header
    status: sequence[DiagnosticStatus]


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]


def yaw(q):
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, default=0)
    ap.add_argument("--namespace", default="")
    ap.add_argument("--timeout", type=float, default=60.0)
    ap.add_argument("--late", type=float, default=0.0, help="seconds to wait before joining")
    ap.add_argument(
        "--cmd-vel",
        type=float,
        default=None,
        help="also drive: publish this forward speed (m/s) on /cmd_vel at 10 Hz for --drive seconds",
    )
    ap.add_argument("--drive", type=float, default=3.0)
    a = ap.parse_args()
    time.sleep(a.late)
    dp = DomainParticipant(a.domain)
    reliable = Qos(
        Policy.Reliability.Reliable(duration(seconds=1)),
        Policy.Durability.Volatile,
        Policy.History.KeepLast(10),
    )
    latched = Qos(
        Policy.Reliability.Reliable(duration(seconds=1)),
        Policy.Durability.TransientLocal,
        Policy.History.KeepLast(1),
    )
    ns = a.namespace.strip("/")
    prefix = "rt/" + (ns + "/" if ns else "")
    readers = {
        "/scan": DataReader(dp, Topic(dp, prefix + "scan", LaserScan), qos=reliable),
        "/pose": DataReader(dp, Topic(dp, prefix + "pose", PoseWithCovarianceStamped), qos=reliable),
        "/tf": DataReader(dp, Topic(dp, prefix + "tf", TFMessage), qos=reliable),
        "/tf_static": DataReader(dp, Topic(dp, prefix + "tf_static", TFMessage), qos=latched),
        "/map": DataReader(dp, Topic(dp, prefix + "map", OccupancyGrid), qos=latched),
        "/diagnostics": DataReader(
            dp, Topic(dp, prefix + "diagnostics", DiagnosticArray), qos=reliable
        ),
    }
    got = {k: [] for k in readers}
    driver = None
    if a.cmd_vel is not None:
        from cyclonedds.pub import DataWriter

        driver = DataWriter(dp, Topic(dp, prefix + "cmd_vel", Twist), qos=reliable)
    started = time.monotonic()
    deadline = started + a.timeout
    first_at = {}
    def enough():
        once = ("/tf_static", "/map", "/diagnostics")
        return all(got[k] for k in once) and all(
            len(v) >= 3 for k, v in got.items() if k not in once
        )

    drive_until = None
    next_command = 0.0
    while time.monotonic() < deadline:
        now = time.monotonic()
        if enough():
            if driver is None:
                break
            if drive_until is None:
                drive_until = now + a.drive
                report_start = got["/pose"][-1]
            if now >= drive_until:
                break
            if now >= next_command:
                driver.write(Twist(linear=Vector3(a.cmd_vel, 0.0, 0.0), angular=Vector3(0.0, 0.0, 0.0)))
                next_command = now + 0.1
        for k, r in readers.items():
            for s in r.take(N=10):
                got[k].append(s)
                first_at.setdefault(k, time.monotonic() - started)
        time.sleep(0.02)
    report = {k: len(v) for k, v in got.items()}
    report["seconds_to_first"] = first_at
    if got["/scan"]:
        s = got["/scan"][-1]
        report["scan"] = {
            "frame_id": s.header.frame_id,
            "stamp": s.header.stamp.sec + s.header.stamp.nanosec * 1e-9,
            "beams": len(s.ranges),
            "angle_min": s.angle_min,
            "angle_increment": s.angle_increment,
            "range_max": s.range_max,
            "time_increment": s.time_increment,
            "infinite": sum(1 for r in s.ranges if math.isinf(r)),
        }
    if got["/pose"]:
        p = got["/pose"][-1]
        report["pose"] = {
            "frame_id": p.header.frame_id,
            "x": p.pose.pose.position.x,
            "y": p.pose.pose.position.y,
            "yaw": yaw(p.pose.pose.orientation),
            "var_x": p.pose.covariance[0],
            "var_yaw": p.pose.covariance[35],
        }
    if got["/tf"]:
        report["tf"] = [
            [t.header.frame_id, t.child_frame_id] for t in got["/tf"][-1].transforms
        ]
    if got["/tf_static"]:
        report["tf_static"] = [
            [t.header.frame_id, t.child_frame_id] for t in got["/tf_static"][-1].transforms
        ]
    if got["/map"]:
        m = got["/map"][-1]
        data = list(m.data)
        report["map"] = {
            "frame_id": m.header.frame_id,
            "resolution": m.info.resolution,
            "cells": m.info.width * m.info.height,
            "data": len(data),
            "free": data.count(0),
            "occupied": data.count(100),
            "unknown": data.count(-1),
        }
    if got["/diagnostics"]:
        d = got["/diagnostics"][-1]
        report["diagnostics"] = {
            st.name: {"level": st.level, "message": st.message, "keys": [kv.key for kv in st.values]}
            for st in d.status
        }
    if driver is not None and drive_until is not None:
        # Let the last commands' motion show in the poses.
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            for s in readers["/pose"].take(N=10):
                got["/pose"].append(s)
            time.sleep(0.02)
        a0, a1 = report_start.pose.pose.position, got["/pose"][-1].pose.pose.position
        report["driven"] = {"dx": a1.x - a0.x, "dy": a1.y - a0.y, "seconds": a.drive}
    print(json.dumps(report))
    sys.exit(0 if all(got.values()) else 1)


if __name__ == "__main__":
    main()
