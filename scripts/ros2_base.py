#!/usr/bin/env python3
"""A ROS 2 base driver on an independent DDS stack (PyPI `cyclonedds`, no
ROS installation), as a holonomic base's driver node behaves: it listens
to /cmd_vel (geometry_msgs/Twist, robot frame), integrates the commanded
velocity, and publishes nav_msgs/Odometry on /odom at 50 Hz (frame odom,
child base_link, stamped on the wall clock).

    python3 scripts/ros2_base.py --domain 0 --seconds 20 [--silent-at 10 --silent-for 3] [--localhost] [--tf]

With --tf the odometry goes out as the transform odom -> base_link on /tf
(tf2_msgs/TFMessage) instead, as drivers that publish only TF do.

With --silent-at T it stops publishing odometry T seconds after the first
command arrives, for --silent-for seconds, as a driver that hangs would,
and keeps listening. Prints one JSON report: the commands heard (count,
moving ones, the fastest), the distance driven, and around the silence
how soon a stop came and whether a moving command came after that.
"""
import argparse
import json
import math
import os
import sys
import time

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

sys.path.insert(0, os.path.dirname(__file__))
from ros2_types import (  # noqa: E402
    Header,
    Odometry,
    Point,
    Pose,
    PoseWithCovariance,
    Quaternion,
    TFMessage,
    Time,
    Transform,
    TransformStamped,
    Twist,
    TwistWithCovariance,
    Vector3,
    localhost_only,
)

RATE = 50.0


def stamp(t):
    sec = math.floor(t)
    return Time(sec=int(sec), nanosec=int((t - sec) * 1e9))


def moving(c):
    return abs(c.linear.x) + abs(c.linear.y) + abs(c.angular.z) > 1e-9


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--silent-at", type=float, default=None)
    ap.add_argument("--silent-for", type=float, default=3.0)
    ap.add_argument("--localhost", action="store_true")
    ap.add_argument("--tf", action="store_true", help="odometry as odom -> base_link on /tf")
    a = ap.parse_args()
    if a.localhost:
        localhost_only()
    dp = DomainParticipant(a.domain)
    qos = Qos(
        Policy.Reliability.Reliable(duration(seconds=1)),
        Policy.Durability.Volatile,
        Policy.History.KeepLast(10),
    )
    if a.tf:
        odom = DataWriter(dp, Topic(dp, "rt/tf", TFMessage), qos=qos)
    else:
        odom = DataWriter(dp, Topic(dp, "rt/odom", Odometry), qos=qos)
    cmd = DataReader(dp, Topic(dp, "rt/cmd_vel", Twist), qos=qos)
    x = y = theta = 0.0
    vel = Twist(linear=Vector3(0.0, 0.0, 0.0), angular=Vector3(0.0, 0.0, 0.0))
    heard = []  # (monotonic time, moving)
    fastest = 0.0
    driven = 0.0
    first_command = None
    start = time.monotonic()
    last = start
    next_odom = start
    while time.monotonic() - start < a.seconds:
        now = time.monotonic()
        dt, last = now - last, now
        # Holonomic: the robot-frame velocity turned into the odometry frame.
        c, s = math.cos(theta), math.sin(theta)
        dx = (vel.linear.x * c - vel.linear.y * s) * dt
        dy = (vel.linear.x * s + vel.linear.y * c) * dt
        x, y, theta = x + dx, y + dy, theta + vel.angular.z * dt
        driven += math.hypot(dx, dy)
        for m in cmd.take(N=50):
            vel = m
            heard.append((now, moving(m)))
            fastest = max(fastest, math.hypot(m.linear.x, m.linear.y))
            if first_command is None:
                first_command = now
        silent = (
            a.silent_at is not None
            and first_command is not None
            and 0.0 <= now - first_command - a.silent_at < a.silent_for
        )
        if now >= next_odom and not silent:
            next_odom = now + 1.0 / RATE
            q = Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))
            header = Header(stamp=stamp(time.time()), frame_id="odom")
            if a.tf:
                tf = Transform(translation=Vector3(x, y, 0.0), rotation=q)
                message = TFMessage(
                    transforms=[
                        TransformStamped(header=header, child_frame_id="base_link", transform=tf)
                    ]
                )
            else:
                message = Odometry(
                    header=header,
                    child_frame_id="base_link",
                    pose=PoseWithCovariance(
                        pose=Pose(position=Point(x=x, y=y, z=0.0), orientation=q),
                        covariance=[0.0] * 36,
                    ),
                    twist=TwistWithCovariance(twist=vel, covariance=[0.0] * 36),
                )
            odom.write(message)
        time.sleep(0.005)
    report = {
        "commands": len(heard),
        "moving": sum(1 for _, m in heard if m),
        "fastest": fastest,
        "driven": driven,
    }
    if a.silent_at is not None and first_command is not None:
        t0 = first_command + a.silent_at
        t1 = t0 + a.silent_for
        during = [(t - t0, m) for t, m in heard if t0 <= t < t1]
        stops = [t for t, m in during if not m]
        report["silence"] = {
            "first_stop_after": stops[0] if stops else None,
            "last_moving_after": max((t for t, m in during if m), default=None),
            "commands": len(during),
        }
        report["moving_after_silence"] = sum(1 for t, m in heard if m and t >= t1)
    print(json.dumps(report))


if __name__ == "__main__":
    main()
