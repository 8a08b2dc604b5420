#!/usr/bin/env python3
"""Fake holonomic base speaking the clsmap line protocol over TCP.

Integrates received `VEL vx vy omega` commands (m/s, m/s, rad/s, robot frame)
into a pose, sends `ODOM t x y theta` at 50 Hz (t: this script's monotonic
clock, s) and `HEALTH OK` once a second; stops when no command arrived for
0.3 s. To bridge a real base, replace the integration with the base's own
odometry and the velocity handling with its motor interface.
Python 3 standard library only. Serves one client at a time.
"""
import argparse
import math
import socket
import time

ODOM_PERIOD = 1.0 / 50.0  # s
HEALTH_PERIOD = 1.0  # s
COMMAND_TIMEOUT = 0.3  # s without VEL/STOP before stopping


def serve(conn):
    conn.settimeout(0.002)  # recv timeout doubles as the loop's sleep
    x = y = theta = 0.0
    vel = (0.0, 0.0, 0.0)
    last = last_cmd = next_odom = next_health = time.monotonic()
    pending = b""
    while True:
        try:
            data = conn.recv(4096)
            if not data:
                return  # client closed
            pending += data
        except socket.timeout:
            pass
        now = time.monotonic()
        while b"\n" in pending:
            line, pending = pending.split(b"\n", 1)
            f = line.decode("ascii", "replace").split()
            if f == ["STOP"]:
                vel, last_cmd = (0.0, 0.0, 0.0), now
            elif len(f) == 4 and f[0] == "VEL":
                try:
                    v = tuple(float(s) for s in f[1:])
                    vel = v if all(map(math.isfinite, v)) else (0.0, 0.0, 0.0)
                except ValueError:
                    vel = (0.0, 0.0, 0.0)
                last_cmd = now
        if now - last_cmd > COMMAND_TIMEOUT:
            vel = (0.0, 0.0, 0.0)
        dt, last = now - last, now
        vx, vy, omega = vel
        mid = theta + 0.5 * omega * dt  # midpoint heading over the step
        x += (vx * math.cos(mid) - vy * math.sin(mid)) * dt
        y += (vx * math.sin(mid) + vy * math.cos(mid)) * dt
        theta = math.remainder(theta + omega * dt, math.tau)
        out = ""
        if now >= next_odom:
            out += f"ODOM {now:.4f} {x:.6f} {y:.6f} {theta:.6f}\n"
            next_odom += ODOM_PERIOD
            if next_odom < now:  # fell behind: skip, do not burst
                next_odom = now + ODOM_PERIOD
        if now >= next_health:
            out += "HEALTH OK\n"
            next_health += HEALTH_PERIOD
        if out:
            conn.sendall(out.encode("ascii"))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=7300, help="0 picks a free port")
    p.add_argument("--once", action="store_true", help="exit after one client")
    args = p.parse_args()
    with socket.create_server((args.host, args.port)) as srv:
        print("listening on %s:%d" % srv.getsockname()[:2], flush=True)
        while True:
            conn, peer = srv.accept()
            with conn:
                try:
                    serve(conn)
                except OSError as e:  # reset, broken pipe, send timeout
                    print(f"client {peer[0]}:{peer[1]}: {e}", flush=True)
            if args.once:
                return


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        pass
