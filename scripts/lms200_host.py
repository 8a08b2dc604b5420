#!/usr/bin/env python3
"""An independent LMS200 host, written from the telegram listing alone and
using nothing but the Python standard library (termios, os): it opens a
serial port (a real sensor, or `clsmap emulate`), talks to it as a plain
host program would, and prints what it found as one JSON object.

    scripts/lms200_host.py --port /tmp/lms200 [--baud 38400] [--pause 0.05]
        [--stream-seconds 3]

Steps: at 9600 Bd a status request (31), the type request (3A), a variant
change to 100 deg / 0.25 deg (3B) and back, each read back from the status; a baud
change (20 40/41/42) answered at the old speed, then the host's own speed
switched and, after `--pause` seconds, a status request at the new speed;
continuous output of all values (20 24) counted for `--stream-seconds`;
back to values on request (20 25) and to 9600 Bd. Exit status 0 when every
step got its reply, 1 otherwise (the JSON says which step failed).
"""

import argparse
import json
import os
import select
import sys
import termios
import time

STX = 0x02
ACK = 0x06
NAK = 0x15
# Longest quiet inside a sensor telegram before it counts as cut (s): the
# listing allows 14 ms between bytes; the rest is slack for a loaded host.
FRAME_GAP = 0.25

SPEEDS = {
    9600: (termios.B9600, 0x42),
    19200: (termios.B19200, 0x41),
    38400: (termios.B38400, 0x40),
}


def crc16(data):
    """The telegram listing's CRC: polynomial 0x8005 shifted in from the
    high bit, with the previous byte folded in (TL section 4.2)."""
    crc = 0
    prev = 0
    for byte in data:
        crc16_val = (prev << 8) | byte
        if crc & 0x8000:
            crc = ((crc & 0x7FFF) << 1) ^ 0x8005
        else:
            crc = crc << 1
        crc ^= crc16_val
        crc &= 0xFFFF
        prev = byte
    return crc


def telegram(payload, address=0x00):
    body = bytes([STX, address, len(payload) & 0xFF, len(payload) >> 8]) + bytes(payload)
    crc = crc16(body)
    return body + bytes([crc & 0xFF, crc >> 8])


class Port:
    def __init__(self, path):
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
        self.buf = bytearray()
        self.set_speed(9600)

    def set_speed(self, bps):
        attrs = termios.tcgetattr(self.fd)
        iflag, oflag, cflag, lflag, ispeed, ospeed, cc = attrs
        # Raw 8N1, no flow control.
        iflag = 0
        oflag = 0
        lflag = 0
        cflag = termios.CS8 | termios.CREAD | termios.CLOCAL
        speed = SPEEDS[bps][0]
        cc[termios.VMIN] = 0
        cc[termios.VTIME] = 0
        termios.tcsetattr(self.fd, termios.TCSANOW,
                          [iflag, oflag, cflag, lflag, speed, speed, cc])

    def write(self, data):
        os.write(self.fd, data)

    def fill(self, deadline):
        now = time.monotonic()
        if now >= deadline:
            return False
        ready, _, _ = select.select([self.fd], [], [], deadline - now)
        if not ready:
            return False
        try:
            chunk = os.read(self.fd, 4096)
        except OSError:
            return False
        self.buf.extend(chunk)
        return True

    def next_telegram(self, deadline):
        """The next telegram with a valid CRC from the sensor (address bit 7
        set); bytes before it (ACK, NAK, noise) are returned too."""
        skipped = bytearray()
        while True:
            while len(self.buf) >= 4:
                if self.buf[0] != STX or not (self.buf[1] & 0x80):
                    skipped.append(self.buf.pop(0))
                    continue
                length = self.buf[2] | (self.buf[3] << 8)
                if length > 1000:
                    skipped.append(self.buf.pop(0))
                    continue
                total = 4 + length + 2
                if len(self.buf) < total:
                    # A request cuts the telegram on the line short (the
                    # stop of a stream, say): when the line goes quiet
                    # inside a frame, it was cut, and the next telegram
                    # starts inside the bytes it claimed.
                    quiet = min(deadline, time.monotonic() + FRAME_GAP)
                    if not self.fill(quiet):
                        if time.monotonic() >= deadline:
                            return None, bytes(skipped)
                        skipped.append(self.buf.pop(0))
                    continue
                frame = bytes(self.buf[:total])
                crc = frame[-2] | (frame[-1] << 8)
                if crc16(frame[:-2]) == crc:
                    del self.buf[:total]
                    return frame, bytes(skipped)
                skipped.append(self.buf.pop(0))
            if not self.fill(deadline):
                return None, bytes(skipped)


def request(port, payload, reply_code, timeout=1.0):
    """Sends `payload` and waits for the reply with `reply_code`; returns
    (payload of the reply after the code, acknowledged)."""
    port.buf.clear()
    port.write(telegram(payload))
    deadline = time.monotonic() + timeout
    acked = False
    while True:
        frame, skipped = port.next_telegram(deadline)
        acked = acked or (ACK in skipped)
        if frame is None:
            return None, acked
        data = frame[4:-2]
        if data and data[0] == reply_code:
            return data[1:], acked


def parse_status(data):
    """The fields of a B1 reply this host knows (offsets after the reply
    code; the STATUS byte is the last)."""
    if data is None or len(data) < 152:
        return None
    return {
        "length": len(data),
        "software": data[0:7].decode("ascii", "replace"),
        "operating_mode": data[7],
        "scan_angle_deg": data[106] | (data[107] << 8),
        "resolution_centideg": data[108] | (data[109] << 8),
        "units_code": data[121],
        "measuring_mode": data[101],
        "address": data[119],
        "device_status": data[8],
        "variant": data[17],
        "permanent_baud": data[118],
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--port", required=True)
    ap.add_argument("--baud", type=int, default=38400, choices=sorted(SPEEDS))
    ap.add_argument("--pause", type=float, default=0.0)
    ap.add_argument("--stream-seconds", type=float, default=3.0)
    args = ap.parse_args()

    report = {"ok": False}
    port = Port(args.port)
    try:
        status, acked = request(port, [0x31], 0xB1)
        report["status_9600"] = parse_status(status)
        report["status_9600_acked"] = acked
        if status is None:
            report["failed"] = "status request at 9600 Bd"
            return report
        kind, _ = request(port, [0x3A], 0xBA)
        report["type"] = kind[:-1].decode("ascii", "replace") if kind else None

        # Another variant (3B: angle, resolution in 1/100 deg), as the
        # status reply then reports it, and back to 180 deg / 0.5 deg.
        variants = []
        for angle, res in [(100, 25), (180, 50)]:
            changed, _ = request(port, [0x3B, angle & 0xFF, angle >> 8, res & 0xFF, res >> 8], 0xBB)
            if changed is None or changed[0] != 0x01:
                report["failed"] = "variant %d/%d" % (angle, res)
                return report
            status, _ = request(port, [0x31], 0xB1)
            fields = parse_status(status) or {}
            variants.append([fields.get("scan_angle_deg"), fields.get("resolution_centideg")])
        report["variants_in_status"] = variants

        if args.baud != 9600:
            changed, _ = request(port, [0x20, SPEEDS[args.baud][1]], 0xA0)
            if changed is None or changed[0] != 0x00:
                report["failed"] = "baud change to %d" % args.baud
                return report
            port.set_speed(args.baud)
            time.sleep(args.pause)
            status, acked = request(port, [0x31], 0xB1)
            report["status_after_change"] = parse_status(status)
            report["first_request_after_change_answered"] = status is not None
            if status is None:
                report["failed"] = "first request at %d Bd" % args.baud
                return report

        started, _ = request(port, [0x20, 0x24], 0xA0)
        if started is None or started[0] != 0x00:
            report["failed"] = "continuous output"
            return report
        t0 = time.monotonic()
        deadline = t0 + args.stream_seconds
        scans = []
        while True:
            frame, _ = port.next_telegram(deadline)
            if frame is None:
                break
            if frame[4] == 0xB0:
                scans.append(time.monotonic())
        report["scans"] = len(scans)
        if len(scans) >= 2:
            report["scan_rate_hz"] = (len(scans) - 1) / (scans[-1] - scans[0])
        # The reply follows the telegram in flight (0.4 s at 19200 Bd); the
        # rest is slack for a loaded machine running the emulator.
        stopped, _ = request(port, [0x20, 0x25], 0xA0, timeout=5.0)
        if stopped is None:
            report["failed"] = "values on request"
            return report
        if args.baud != 9600:
            back, _ = request(port, [0x20, 0x42], 0xA0)
            if back is None:
                report["failed"] = "baud change back to 9600"
                return report
            port.set_speed(9600)
            time.sleep(args.pause)
            status, _ = request(port, [0x31], 0xB1)
            report["first_request_back_at_9600_answered"] = status is not None
            if status is None:
                report["failed"] = "first request back at 9600 Bd"
                return report
        report["ok"] = True
        return report
    finally:
        os.close(port.fd)


if __name__ == "__main__":
    result = main()
    print(json.dumps(result, sort_keys=True))
    sys.exit(0 if result.get("ok") else 1)
