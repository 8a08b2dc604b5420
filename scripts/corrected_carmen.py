#!/usr/bin/env python3
"""Turn a SLAM-corrected CARMEN log into a mapping test with a known answer.

The corrected logs of the Radish collection (`*-corrected.log`: GMapping's
output, one FLASER scan per metre or so, each at its corrected pose) hold
no usable odometry: their FLASER odometry fields are the corrected poses.
This keeps each scan's ranges, gives it odometry synthesised from the
corrected motion with seeded noise, and writes three files:

    OUT.clf        the scans with the synthesised odometry (FLASER lines)
    OUT.tum        the corrected poses: the reference
    OUT.relations  relations between reference poses, as Kümmerle et al.
                   (2009) score them: each scan to the next five, and each
                   scan to up to three revisits (30 scans or more later,
                   within 3 m and 1 rad)

    scripts/corrected_carmen.py IN.log OUT [--seed 1]
    clsmap map OUT.clf --out DIR --relations OUT.relations

The noise: per log, a distance scale error (σ 2 %) and a heading drift
(σ 0.005 rad/m); per step, σ 0.02 m/m + 3 mm along the motion, 0.01 m/m
+ 3 mm across it, and 0.03 rad/rad + 0.005 rad/m + 0.002 rad in heading.
`--seed 0` gives the corrected poses themselves as odometry. Stamps are
the log's, or one second apart where the log's do not increase.
"""
import argparse
import math
import random
import sys

NEXT = 5
REVISIT_AFTER = 30
REVISIT_STRIDE = 7
REVISIT_DISTANCE = 3.0
REVISIT_TURN = 1.0
REVISITS_PER_SCAN = 3


def wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def between(a, b):
    """b in the frame of a; poses are (x, y, theta)."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    c, s = math.cos(a[2]), math.sin(a[2])
    return c * dx + s * dy, -s * dx + c * dy, wrap(b[2] - a[2])


def read_scans(path):
    """(ranges as text, corrected pose, stamp) of each FLASER line."""
    scans = []
    with open(path) as src:
        for number, line in enumerate(src, 1):
            fields = line.split()
            if not fields or fields[0] != "FLASER":
                continue
            try:
                n = int(fields[1])
                pose = tuple(float(v) for v in fields[n + 2 : n + 5])
                stamp = float(fields[n + 8])
                ranges = fields[2 : n + 2]
                if len(ranges) != n or not all(map(math.isfinite, (*pose, stamp))):
                    raise ValueError
            except (ValueError, IndexError):
                raise SystemExit(f"{path}:{number}: malformed FLASER line")
            scans.append((ranges, pose, stamp))
    return scans


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input")
    ap.add_argument("output", help="prefix of the three files written")
    ap.add_argument("--seed", type=int, default=1, help="0 = exact odometry (default 1)")
    args = ap.parse_args()
    scans = read_scans(args.input)
    if len(scans) < 2:
        print(f"{args.input}: fewer than two FLASER scans", file=sys.stderr)
        return 1
    stamps = [s[2] for s in scans]
    if not all(b > a for a, b in zip(stamps, stamps[1:])):
        stamps = [1000.0 + i for i in range(len(scans))]
    rng = random.Random(args.seed)
    noisy = args.seed != 0
    gauss = rng.gauss if noisy else (lambda mean, sigma: mean)
    scale = gauss(1.0, 0.02)
    drift = gauss(0.0, 0.005)

    odometry = [(0.0, 0.0, 0.0)]
    for a, b in zip(scans, scans[1:]):
        fx, fy, turn = between(a[1], b[1])
        d = math.hypot(fx, fy)
        fx = scale * fx + gauss(0.0, 0.02 * d + 0.003)
        fy = scale * fy + gauss(0.0, 0.01 * d + 0.003)
        turn += drift * d + gauss(0.0, 0.03 * abs(turn) + 0.005 * d + 0.002)
        x, y, th = odometry[-1]
        c, s = math.cos(th), math.sin(th)
        odometry.append((x + c * fx - s * fy, y + s * fx + c * fy, th + turn))

    with open(args.output + ".clf", "x") as out:
        out.write(f"# scans of {args.input}, odometry synthesised with seed {args.seed}\n")
        for (ranges, _, _), (x, y, th), t in zip(scans, odometry, stamps):
            pose = f"{x:.6f} {y:.6f} {th:.6f}"
            out.write(f"FLASER {len(ranges)} {' '.join(ranges)} {pose} {pose} {t:.6f} synth {t:.6f}\n")
    with open(args.output + ".tum", "x") as out:
        out.write("# timestamp x y z qx qy qz qw\n")
        for (_, (x, y, th), _), t in zip(scans, stamps):
            out.write(f"{t:.6f} {x:.6f} {y:.6f} 0 0 0 {math.sin(th / 2):.9f} {math.cos(th / 2):.9f}\n")
    count = 0
    with open(args.output + ".relations", "x") as out:

        def relation(i: int, j: int) -> None:
            dx, dy, dth = between(scans[i][1], scans[j][1])
            out.write(f"{stamps[i]:.6f} {stamps[j]:.6f} {dx:.6f} {dy:.6f} 0 0 0 {dth:.6f}\n")

        for i, (_, a, _) in enumerate(scans):
            for j in range(i + 1, min(i + 1 + NEXT, len(scans))):
                relation(i, j)
                count += 1
            found = 0
            for j in range(i + REVISIT_AFTER, len(scans), REVISIT_STRIDE):
                b = scans[j][1]
                near = math.hypot(b[0] - a[0], b[1] - a[1]) < REVISIT_DISTANCE
                if near and abs(wrap(b[2] - a[2])) < REVISIT_TURN:
                    relation(i, j)
                    count += 1
                    found += 1
                    if found == REVISITS_PER_SCAN:
                        break
    print(f"{len(scans)} scans, {count} relations", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
