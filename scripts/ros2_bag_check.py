#!/usr/bin/env python3
"""Reads a rosbag2 MCAP bag with PyPI `rosbags` (an independent reader)
and decodes every message with its ROS 2 Humble type store; prints one
JSON object: per topic its type and message count, the first LaserScan's
fields, and the bytes on /lms200/recording. Exits non-zero if anything
fails to read or decode.

    python3 scripts/ros2_bag_check.py BAG.mcap
"""
import json
import math
import sys

from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore


def finite(v):
    return v if math.isfinite(v) else str(v)


def main(path):
    store = get_typestore(Stores.ROS2_HUMBLE)
    topics = {}
    first_scan = None
    recording = bytearray()
    last_stamp = None
    stamps_increase = True
    with Reader(path) as reader:
        for conn in reader.connections:
            topics[conn.topic] = {"type": conn.msgtype, "count": 0}
        for conn, _t, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            topics[conn.topic]["count"] += 1
            if conn.msgtype == "sensor_msgs/msg/LaserScan":
                stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
                if last_stamp is not None and stamp <= last_stamp:
                    stamps_increase = False
                last_stamp = stamp
                if first_scan is None:
                    first_scan = {
                        "frame_id": msg.header.frame_id,
                        "angle_min": msg.angle_min,
                        "angle_max": msg.angle_max,
                        "angle_increment": msg.angle_increment,
                        "time_increment": msg.time_increment,
                        "scan_time": msg.scan_time,
                        "range_max": msg.range_max,
                        "beams": len(msg.ranges),
                        "ranges": [finite(float(r)) for r in msg.ranges[:5]],
                    }
            if conn.topic == "/lms200/recording":
                recording.extend(bytes(msg.data))
    print(
        json.dumps(
            {
                "topics": topics,
                "first_scan": first_scan,
                "scan_stamps_increase": stamps_increase,
                "recording_bytes": len(recording),
                "recording_head": bytes(recording[:8]).hex(),
            }
        )
    )


if __name__ == "__main__":
    main(sys.argv[1])
