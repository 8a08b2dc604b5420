#!/usr/bin/env python3
"""Reverse a CARMEN log in time, with its relations file: the same building
driven the other way round, so loops close in another order and from the
other side. A scan at time t moves to t_first + t_last - t; its ranges and
odometry stay as they are (the odometry's steps are walked backwards). A
relation between t1 and t2 becomes one between the reversed times, with
the pose of the earlier reversed scan in the frame of the later one (its
inverse). Only FLASER lines are kept, after the leading comment lines.

    scripts/reverse_carmen.py IN.clf IN.relations OUT.clf OUT.relations
"""
import argparse
import math
import sys


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("relations")
    ap.add_argument("out_log")
    ap.add_argument("out_relations")
    args = ap.parse_args()
    header, scans = [], []
    with open(args.log) as src:
        for number, line in enumerate(src, 1):
            fields = line.split()
            if not fields:
                continue
            if fields[0].startswith("#"):
                if not scans:
                    header.append(line)
                continue
            if fields[0] != "FLASER":
                continue
            try:
                n = int(fields[1])
                t = float(fields[n + 8])
                float(fields[n + 10])
            except (ValueError, IndexError):
                print(f"{args.log}:{number}: malformed FLASER line", file=sys.stderr)
                return 1
            scans.append((t, n, fields))
    if not scans:
        print(f"{args.log}: no FLASER scans", file=sys.stderr)
        return 1
    first, last = scans[0][0], scans[-1][0]
    span = first + last
    with open(args.out_log, "x") as out:
        out.writelines(header)
        for t, n, fields in reversed(scans):
            fields[n + 8] = f"{span - t:.6f}"
            fields[n + 10] = f"{last - t:.6f}"
            out.write(" ".join(fields) + "\n")
    written = 0
    with open(args.relations) as src, open(args.out_relations, "x") as out:
        for number, line in enumerate(src, 1):
            fields = line.split()
            if not fields or fields[0].startswith("#"):
                continue
            try:
                t1, t2, x, y, _z, _roll, _pitch, yaw = (float(v) for v in fields[:8])
            except ValueError:
                print(f"{args.relations}:{number}: malformed relation", file=sys.stderr)
                return 1
            c, s = math.cos(yaw), math.sin(yaw)
            ix, iy = -(c * x + s * y), s * x - c * y
            out.write(
                f"{span - t2:.5f} {span - t1:.5f} {ix:.5f} {iy:.5f} 0.00000 "
                f"0.00000 0.00000 {-yaw:.5f}\n"
            )
            written += 1
    print(f"reversed {len(scans)} scans and {written} relations", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
