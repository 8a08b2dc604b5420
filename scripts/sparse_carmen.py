#!/usr/bin/env python3
"""Thin a CARMEN log the way GMapping's update rule does: keep a FLASER or
ROBOTLASER1 scan only when the odometry moved at least --travel metres or
turned at least --turn radians since the last kept scan (the first scan is
kept). Other lines pass through unchanged.

    scripts/sparse_carmen.py IN.clf OUT.clf [--travel 0.5] [--turn 0.5]
"""
import argparse
import math
import sys


def odometry(fields):
    """The odometry pose (x, y, theta) of a FLASER or ROBOTLASER1 line."""
    if fields[0] == "FLASER":
        n = int(fields[1])
        pose = fields[n + 5 : n + 8]
    else:
        # type, start angle, fov, resolution, max range, accuracy,
        # remission mode, the readings, the remissions, the laser pose,
        # then the robot's.
        n = int(fields[8])
        m = int(fields[9 + n])
        first = 10 + n + m + 3
        pose = fields[first : first + 3]
    if len(pose) != 3:
        raise ValueError("short line")
    return tuple(float(v) for v in pose)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input")
    ap.add_argument("output")
    ap.add_argument("--travel", type=float, default=0.5, help="m (default 0.5)")
    ap.add_argument("--turn", type=float, default=0.5, help="rad (default 0.5)")
    args = ap.parse_args()
    kept = total = 0
    last = None
    with open(args.input) as src, open(args.output, "x") as out:
        for number, line in enumerate(src, 1):
            fields = line.split()
            if not fields or fields[0] not in ("FLASER", "ROBOTLASER1"):
                out.write(line)
                continue
            total += 1
            try:
                ox, oy, ot = odometry(fields)
            except (ValueError, IndexError):
                print(f"{args.input}:{number}: malformed {fields[0]} line", file=sys.stderr)
                return 1
            if last is not None:
                dx, dy = ox - last[0], oy - last[1]
                dt = math.atan2(math.sin(ot - last[2]), math.cos(ot - last[2]))
                if math.hypot(dx, dy) < args.travel and abs(dt) < args.turn:
                    continue
            last = (ox, oy, ot)
            kept += 1
            out.write(line)
    print(f"kept {kept} of {total} scans", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
