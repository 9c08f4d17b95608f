#!/usr/bin/env python3
"""Draws class.png of the `town` world the world-stage fixtures of `spomp validate` use.

80 x 60 pixels at 1 m (world.yaml): an east-west road (y 4..16 m) and a north-south road
(x 30..40 m), a building (x 50..70, y 30..50), a parking lot with one cluster of five vehicles
(x 5..23, y 20..25), grass elsewhere; the default class table's colours. Standard library only;
the output is byte-for-byte reproducible.
"""

import os
import struct
import zlib

W, H = 80, 60
ROAD, GRASS, BUILDING, VEHICLE = (128, 64, 128), (152, 251, 152), (70, 70, 70), (0, 0, 142)
img = [[GRASS for _ in range(W)] for _ in range(H)]


def rect(x0, y0, x1, y1, colour):
    """Fills map x0 <= x < x1, y0 <= y < y1 (metres, y up; row 0 of the image is north)."""
    for y in range(y0, y1):
        for x in range(x0, x1):
            img[H - 1 - y][x] = colour


rect(0, 4, W, 16, ROAD)
rect(30, 0, 40, H, ROAD)
rect(50, 30, 70, 50, BUILDING)
rect(2, 16, 28, 30, ROAD)  # the parking lot, level with the road
for k in range(5):
    rect(5 + 4 * k, 20, 8 + 4 * k, 25, VEHICLE)

raw = b"".join(b"\x00" + bytes(c for px in row for c in px) for row in img)


def chunk(kind, data):
    body = kind + data
    return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)


with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "class.png"), "wb") as f:
    f.write(b"\x89PNG\r\n\x1a\n")
    f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 2, 0, 0, 0)))
    f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
    f.write(chunk(b"IEND", b""))
