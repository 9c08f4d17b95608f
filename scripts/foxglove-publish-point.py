#!/usr/bin/env python3
"""Publishes one point to a Foxglove WebSocket server the way Foxglove's 3-D panel
"Publish point" does, with nothing but Python's standard library (raw WebSocket frames).

    python3 scripts/foxglove-publish-point.py ws://127.0.0.1:8765 40 12 [--frame map]
        [--topic /clicked_point] [--timeout-s 20]

It connects offering the protocol's original subprotocol `foxglove.websocket.v1` (as
`@foxglove/ws-protocol` clients do), reads `serverInfo`, requires the `clientPublish`
capability, picks the first of the server's `supportedEncodings` it can write (json or cdr,
Foxglove's rule), advertises a `geometry_msgs/PointStamped` client channel, publishes the point,
and waits for the server's status about it. `spomp run --live --live-operator` answers with an
info status when the point goes to the robot as the operator's goal, an error status when it is
refused.

Exit 0: an info status about the point; 1: an error status (printed); 2: no answer, or the
server does not take points.
"""
import argparse
import base64
import json
import os
import socket
import struct
import sys
import time
from urllib.parse import urlparse

SUBPROTOCOL = "foxglove.websocket.v1"
# Foxglove's publication encodings, in the order it tries the server's list.
WRITABLE = ("json", "cdr")


class Socket:
    """A minimal WebSocket client: the handshake, masked frames out, frames in."""

    def __init__(self, url, timeout):
        u = urlparse(url)
        if u.scheme != "ws" or not u.hostname or not u.port:
            raise SystemExit(f"expected ws://HOST:PORT, got {url}")
        self.sock = socket.create_connection((u.hostname, u.port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        request = (
            f"GET / HTTP/1.1\r\nHost: {u.hostname}:{u.port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
            f"Sec-WebSocket-Protocol: {SUBPROTOCOL}\r\n\r\n"
        )
        self.sock.sendall(request.encode())
        self.buf = b""
        while b"\r\n\r\n" not in self.buf:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise SystemExit("the server closed the connection during the handshake")
            self.buf += chunk
        head, self.buf = self.buf.split(b"\r\n\r\n", 1)
        lines = head.decode(errors="replace").split("\r\n")
        if " 101 " not in lines[0] + " ":
            raise SystemExit(f"handshake refused: {lines[0]}")
        protocol = [l.split(":", 1)[1].strip() for l in lines if l.lower().startswith("sec-websocket-protocol:")]
        if protocol != [SUBPROTOCOL]:
            raise SystemExit(f"the server chose subprotocol {protocol}")

    def _read(self, n):
        while len(self.buf) < n:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise EOFError("the server closed the connection")
            self.buf += chunk
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def receive(self):
        """One message: (opcode, payload); fragments joined, pings answered."""
        parts, first_op = [], None
        while True:
            b0, b1 = self._read(2)
            op, fin, n = b0 & 0x0F, b0 & 0x80, b1 & 0x7F
            if n == 126:
                (n,) = struct.unpack(">H", self._read(2))
            elif n == 127:
                (n,) = struct.unpack(">Q", self._read(8))
            mask = self._read(4) if b1 & 0x80 else None
            data = self._read(n)
            if mask:
                data = bytes(c ^ mask[i % 4] for i, c in enumerate(data))
            if op == 0x9:
                self.send(0xA, data)
                continue
            if op == 0x8:
                raise EOFError("the server closed the connection")
            if op != 0x0:
                first_op = op
            parts.append(data)
            if fin:
                return first_op, b"".join(parts)

    def send(self, op, payload):
        mask = os.urandom(4)
        n = len(payload)
        if n < 126:
            head = struct.pack("!BB", 0x80 | op, 0x80 | n)
        elif n < 1 << 16:
            head = struct.pack("!BBH", 0x80 | op, 0x80 | 126, n)
        else:
            head = struct.pack("!BBQ", 0x80 | op, 0x80 | 127, n)
        masked = bytes(c ^ mask[i % 4] for i, c in enumerate(payload))
        self.sock.sendall(head + mask + masked)


def point_message(encoding, frame, x, y):
    """A geometry_msgs/PointStamped as Foxglove's 3-D panel fills it, in `encoding`."""
    now = time.time()
    sec, nsec = int(now), int((now % 1) * 1e9)
    if encoding == "json":
        msg = {"header": {"stamp": {"sec": sec, "nsec": nsec}, "frame_id": frame}, "point": {"x": x, "y": y, "z": 0}}
        return json.dumps(msg).encode()
    # ROS 2 CDR, little-endian: header (int32 sec, uint32 nanosec, string frame_id), then
    # three float64 aligned to 8 bytes (counted after the 4-byte encapsulation header).
    body = struct.pack("<iI", sec, nsec) + struct.pack("<I", len(frame) + 1) + frame.encode() + b"\0"
    body += b"\0" * (-len(body) % 8)
    body += struct.pack("<ddd", x, y, 0.0)
    return b"\x00\x01\x00\x00" + body


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("url")
    ap.add_argument("x", type=float)
    ap.add_argument("y", type=float)
    ap.add_argument("--frame", default="map")
    ap.add_argument("--topic", default="/clicked_point")
    ap.add_argument("--encoding", choices=WRITABLE, help="instead of the server's first writable one")
    ap.add_argument("--timeout-s", type=float, default=20.0)
    args = ap.parse_args()
    deadline = time.monotonic() + args.timeout_s
    ws = Socket(args.url, args.timeout_s)
    info = None
    while info is None:
        op, data = ws.receive()
        if op == 0x1 and json.loads(data).get("op") == "serverInfo":
            info = json.loads(data)
    if "clientPublish" not in info.get("capabilities", []):
        print(f"the server does not take published messages: capabilities {info.get('capabilities')}")
        return 2
    offered = info.get("supportedEncodings", [])
    encoding = args.encoding or next((e for e in offered if e in WRITABLE), None)
    if encoding not in offered:
        print(f"the server takes none of {WRITABLE}: {offered}")
        return 2
    channel = {"id": 1, "topic": args.topic, "encoding": encoding, "schemaName": "geometry_msgs/PointStamped"}
    ws.send(0x1, json.dumps({"op": "advertise", "channels": [channel]}).encode())
    ws.send(0x2, b"\x01" + struct.pack("<I", 1) + point_message(encoding, args.frame, args.x, args.y))
    while time.monotonic() < deadline:
        ws.sock.settimeout(max(0.1, deadline - time.monotonic()))
        try:
            op, data = ws.receive()
        except (socket.timeout, EOFError) as e:
            print(f"no answer: {e}")
            return 2
        if op != 0x1:
            continue
        msg = json.loads(data)
        if msg.get("op") != "status" or not msg.get("message", "").startswith(args.topic + ": "):
            continue
        text = msg["message"]
        if "becomes an operator's goal" in text:
            continue  # the answer to the advertisement; the point's comes next
        print(text)
        return 0 if msg.get("level") == 0 else 1
    print("no answer in time")
    return 2


if __name__ == "__main__":
    sys.exit(main())
