#!/usr/bin/env python3
"""Writes a CARMEN log's laser scans and odometry as a rosbag2 bag in MCAP,
with PyPI `rosbags` (an independent rosbag2 writer), as a ROS 2 user's bag
of the same run would hold them:

    python3 scripts/carmen_to_rosbag2.py IN.clf OUT_BAG_DIR

Each FLASER line becomes a sensor_msgs/LaserScan on /scan (180 degrees,
no-return codes as +inf) and a nav_msgs/Odometry on /odom with the line's
odometry pose, both stamped with the line's ipc timestamp.
"""
import math
import sys

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

NO_RETURN = 81.9

store = get_typestore(Stores.ROS2_HUMBLE)
T = store.types
Time = T["builtin_interfaces/msg/Time"]
Header = T["std_msgs/msg/Header"]
LaserScan = T["sensor_msgs/msg/LaserScan"]
Odometry = T["nav_msgs/msg/Odometry"]
Pwc = T["geometry_msgs/msg/PoseWithCovariance"]
Pose = T["geometry_msgs/msg/Pose"]
Point = T["geometry_msgs/msg/Point"]
Quaternion = T["geometry_msgs/msg/Quaternion"]
Twc = T["geometry_msgs/msg/TwistWithCovariance"]
Twist = T["geometry_msgs/msg/Twist"]
Vector3 = T["geometry_msgs/msg/Vector3"]


def stamp(t):
    ns = round(t * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), ns


def main(src, dst):
    scans = 0
    with Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        scan_c = bag.add_connection("/scan", LaserScan.__msgtype__, typestore=store)
        odom_c = bag.add_connection("/odom", Odometry.__msgtype__, typestore=store)
        with open(src) as f:
            for line in f:
                w = line.split()
                if not w or w[0] != "FLASER":
                    continue
                n = int(w[1])
                ranges = [float(v) for v in w[2 : 2 + n]]
                ox, oy, oth = (float(v) for v in w[5 + n : 8 + n])
                t = float(w[8 + n])
                time, ns = stamp(t)
                header = Header(stamp=time, frame_id="laser")
                r = np.array(
                    [math.inf if (v <= 0 or v >= NO_RETURN) else v for v in ranges],
                    dtype=np.float32,
                )
                # As CARMEN reads FLASER: from -90 degrees, 1 degree apart for
                # 180 or 181 beams, 0.5 for 360 or 361, else over 180 degrees.
                step = {180: 1.0, 181: 1.0, 360: 0.5, 361: 0.5}.get(n)
                inc = math.radians(step) if step else math.pi / (n - 1)
                scan = LaserScan(
                    header=header,
                    angle_min=-math.pi / 2,
                    angle_max=-math.pi / 2 + (n - 1) * inc,
                    angle_increment=inc,
                    time_increment=0.0,
                    scan_time=0.0,
                    range_min=0.0,
                    range_max=NO_RETURN,
                    ranges=r,
                    intensities=np.array([], dtype=np.float32),
                )
                odom = Odometry(
                    header=Header(stamp=time, frame_id="odom"),
                    child_frame_id="base_link",
                    pose=Pwc(
                        pose=Pose(
                            position=Point(x=ox, y=oy, z=0.0),
                            orientation=Quaternion(
                                x=0.0, y=0.0, z=math.sin(oth / 2), w=math.cos(oth / 2)
                            ),
                        ),
                        covariance=np.zeros(36),
                    ),
                    twist=Twc(
                        twist=Twist(linear=Vector3(x=0.0, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0)),
                        covariance=np.zeros(36),
                    ),
                )
                # Odometry first: a scan's odometry is there when it is read.
                bag.write(odom_c, ns, store.serialize_cdr(odom, Odometry.__msgtype__))
                bag.write(scan_c, ns, store.serialize_cdr(scan, LaserScan.__msgtype__))
                scans += 1
    print(f"wrote {scans} scans to {dst}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
