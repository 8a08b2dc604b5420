#!/usr/bin/env python3
"""A ROS 2 subscriber on an independent DDS stack (PyPI `cyclonedds`, no
ROS installation): subscribes to /scan, /pose, /tf, /tf_static, /map,
/cls_map and /diagnostics as RViz would, with the ROS 2 type names and the
message layouts written here from the ROS 2 definitions, waits (bounded)
for samples on each, and prints one JSON report. /tf_static, /map and
/cls_map are read transient-local, so a subscriber that joins after they
were sent still gets them.

    python3 scripts/ros2_subscriber.py --domain 0 --timeout 60 [--namespace /robot1] [--localhost]

--localhost keeps this participant on the loopback interface (as
ROS_LOCALHOST_ONLY=1), discovering peers by unicast on 127.0.0.1.

With --cmd-vel V it then drives the robot: Twist messages on /cmd_vel at
10 Hz for --drive seconds, and reports how far the pose moved.

Exits 1 if a topic saw nothing before the timeout.
"""
import argparse
import json
import math
import sys
import time

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

sys.path.insert(0, __import__("os").path.dirname(__file__))
from ros2_types import (  # noqa: E402
    DiagnosticArray,
    LaserScan,
    MarkerArray,
    OccupancyGrid,
    PoseWithCovarianceStamped,
    TFMessage,
    Twist,
    Vector3,
    localhost_only,
    yaw,
)


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
    ap.add_argument("--localhost", action="store_true", help="loopback only")
    a = ap.parse_args()
    if a.localhost:
        localhost_only()
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
        "/cls_map": DataReader(dp, Topic(dp, prefix + "cls_map", MarkerArray), qos=latched),
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
        once = ("/tf_static", "/map", "/cls_map", "/diagnostics")
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
    if got["/cls_map"]:
        report["cls_map"] = {
            m.ns: {
                "frame_id": m.header.frame_id,
                "type": m.type,
                "action": m.action,
                "points": len(m.points),
                "width": m.scale.x,
            }
            for m in got["/cls_map"][-1].markers
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
