#!/usr/bin/env python3
"""Draws the `hidden-barriers` world of the experience-sharing trial (claim (d) of
experiments/paper.yaml; issue 33): roads whose aerial map misleads.

200 x 110 m at 0.5 m a pixel (world.yaml), the default class table's colours, elevation derived
from the classes (building 12 m, vegetation 1 m, road and gravel flat). Blocks of buildings
between five roads, 10 m wide: a west and an east road (x 0..10 and 190..200 m) joined by a
south, a middle and a north road (y 0..10, 45..55 and 100..110 m). A few gravel lots open onto
the roads (landmarks for the cross-view localizer). The UGVs start on the west road at the
middle road's mouth; the goal is on the east road at its other end.

Two barriers stand across roads, 1 m thick and 1 m high (a hedge of planters under the trees
lining the road): on the middle road, the straight way to the goal, and on the south road, the
next shortest. Seen from above they are road: `class.png` is the ground, `aerial-class.png`
the world seen from above (world.yaml, `layers.aerial`), the road running on under the canopy.
A robot's aerial map shows three open ways, the shortest first; only driving up to a barrier
tells it is shut. The open way is the north road.
Standard library only; the output is byte-for-byte reproducible.
"""

import os
import struct
import zlib

RES = 0.5
W, H = 400, 220
ROAD, GRAVEL = (128, 64, 128), (190, 153, 153)
VEGETATION, BUILDING = (107, 142, 35), (70, 70, 70)
HERE = os.path.dirname(os.path.abspath(__file__))


def blank():
    return [[BUILDING for _ in range(W)] for _ in range(H)]


def fill(img, inside, colour):
    """Paints every pixel whose centre (metres, y up) satisfies `inside`."""
    for row in range(H):
        y = (H - 1 - row + 0.5) * RES
        for col in range(W):
            x = (col + 0.5) * RES
            if inside(x, y):
                img[row][col] = colour


def roads(img):
    fill(img, lambda x, y: x < 10 or x >= 190, ROAD)
    fill(img, lambda x, y: y < 10 or 45 <= y < 55 or y >= 100, ROAD)
    # Gravel lots beside the roads, at irregular places (x0, y0, x1, y1).
    for x0, y0, x1, y1 in [
        (10, 14, 22, 22),
        (46, 55, 58, 63),
        (92, 37, 106, 45),
        (131, 10, 141, 18),
        (70, 92, 84, 100),
        (150, 55, 160, 64),
        (170, 92, 182, 100),
        (10, 78, 18, 90),
    ]:
        fill(img, lambda x, y, b=(x0, y0, x1, y1): b[0] <= x < b[2] and b[1] <= y < b[3], GRAVEL)


# Where the barriers stand (x from, x to), and the roads they shut (y from, y to).
BARRIERS = [((150.0, 151.0), (45.0, 55.0)), ((150.0, 151.0), (0.0, 10.0))]

ground = blank()
roads(ground)
for (x0, x1), (y0, y1) in BARRIERS:
    fill(ground, lambda x, y, x0=x0, x1=x1, y0=y0, y1=y1: x0 <= x < x1 and y0 <= y < y1, VEGETATION)
aerial = blank()
roads(aerial)


def chunk(kind, data):
    body = kind + data
    return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)


def write_png(name, img):
    raw = b"".join(b"\x00" + bytes(c for px in row for c in px) for row in img)
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        f.write(chunk(b"IEND", b""))


write_png("class.png", ground)
write_png("aerial-class.png", aerial)
