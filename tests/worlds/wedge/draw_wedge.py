#!/usr/bin/env python3
"""Draws class.png of the `wedge` world: a dead-end pocket on the way to a goal (issue 33).

60 x 40 m at 0.25 m a pixel (world.yaml), the default class table's colours, elevation derived
from the classes (vegetation 1 m, buildings 12 m, gravel and road flat):
- a road along the west edge (x 0..10 m) and one along the south edge (y 0..4 m), joining a
  parking lot along the east edge (x 46..60 m) with one cluster of three cars (x 50..57,
  y 18..22.5 m): the goal;
- between them a building (x 10..46, y 24..40 m) and 1 m vegetation (x 10..46, y 4..24 m) into
  which a flat gravel wedge opens from the west road: 12 m wide at x = 10 m, closing to its tip
  against the building's wall at x = 40 m. The straight way to the goal runs into the wedge; the
  way that can be driven is the longer one by the south road.
The regression test starts the UGV wedged near the tip, at (36, 23.1) facing east (world.yaml,
wedge-mission.yaml): 1.6 m of gravel across, every side within its terrain analysis's 0.75 m
inflation, so only a recovery gets it out.
Standard library only; the output is byte-for-byte reproducible.
"""

import os
import struct
import zlib

RES = 0.25
W, H = 240, 160
ROAD, GRAVEL = (128, 64, 128), (190, 153, 153)
VEGETATION, BUILDING, VEHICLE = (107, 142, 35), (70, 70, 70), (0, 0, 142)
img = [[VEGETATION for _ in range(W)] for _ in range(H)]


def fill(inside, colour):
    """Paints every pixel whose centre (metres, y up) satisfies `inside`."""
    for row in range(H):
        y = (H - 1 - row + 0.5) * RES
        for col in range(W):
            x = (col + 0.5) * RES
            if inside(x, y):
                img[row][col] = colour


fill(lambda x, y: x < 10 or y < 4 or x >= 46, ROAD)
fill(lambda x, y: 10 <= x < 46 and y >= 24, BUILDING)
# The pocket: under the wall (y < 24 m), above the vegetation's edge from (10, 12) to (40, 24).
MOUTH = 12.0  # width of the pocket at its mouth, metres
fill(lambda x, y: 10 <= x < 40 and y < 24 and y >= 24 - MOUTH + MOUTH / 30 * (x - 10), GRAVEL)
for x0 in (50.0, 52.5, 55.0):
    fill(lambda x, y, x0=x0: x0 <= x < x0 + 2 and 18 <= y < 22.5, VEHICLE)

raw = b"".join(b"\x00" + bytes(c for px in row for c in px) for row in img)


def chunk(kind, data):
    body = kind + data
    return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)


with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "class.png"), "wb") as f:
    f.write(b"\x89PNG\r\n\x1a\n")
    f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 2, 0, 0, 0)))
    f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
    f.write(chunk(b"IEND", b""))
