#!/usr/bin/env python3
"""Draws campus.png, the self-made colour-coded class raster `spomp world import` is tested on.

A 320 x 240 pixel raster (0.5 m per pixel: 160 m x 120 m, north up) in the colours of
campus-classes.yaml: a road grid, grass blocks with buildings, trees, three parking lots with
vehicle clusters, and anti-aliased (blended) road edges and a few stray colours, as rasters
exported from a segmentation tool have. Standard library only; run it from anywhere to
regenerate the PNG next to this script (the output is byte-for-byte reproducible).
"""

import os
import struct
import zlib

W, H = 320, 240
ROAD = (128, 64, 128)
GRASS = (152, 251, 152)
BUILDING = (70, 70, 70)
VEHICLE = (0, 0, 142)
VEGETATION = (107, 142, 35)
TRUNK = (153, 102, 51)
GRAVEL = (190, 153, 153)

img = [[GRASS for _ in range(W)] for _ in range(H)]


def rect(x0, y0, x1, y1, colour):
    """Fills pixels x0 <= x < x1, y0 <= y < y1 (image coordinates, y down)."""
    for y in range(max(0, y0), min(H, y1)):
        for x in range(max(0, x0), min(W, x1)):
            img[y][x] = colour


def disk(cx, cy, r, colour):
    for y in range(cy - r, cy + r + 1):
        for x in range(cx - r, cx + r + 1):
            if 0 <= x < W and 0 <= y < H and (x - cx) ** 2 + (y - cy) ** 2 <= r * r:
                img[y][x] = colour


# Roads, 12 m wide: two east-west, three north-south.
for y0 in (24, 196):
    rect(0, y0, W, y0 + 24, ROAD)
for x0 in (12, 148, 284):
    rect(x0, 0, x0 + 24, H, ROAD)

# Buildings set back from the roads.
rect(56, 64, 120, 100, BUILDING)
rect(56, 120, 96, 176, BUILDING)
rect(196, 60, 264, 92, BUILDING)
rect(300 + 4, 60, 320, 110, BUILDING)

# Parking lots (road surface, level with the road they open onto) with vehicle clusters:
# cars 2 m x 4.5 m (4 x 9 px) in rows, 3 m apart.
def lot(x0, y0, cars, rows=1):
    rect(x0, y0, x0 + 6 * cars + 8, y0 + 14 * rows + 10, ROAD)
    for r in range(rows):
        for k in range(cars):
            rect(x0 + 4 + 6 * k, y0 + 4 + 14 * r, x0 + 8 + 6 * k, y0 + 13 + 14 * r, VEHICLE)


lot(36, 172, 5)            # south-west lot on the southern road (x 36..74, y 172..196)
lot(174, 172, 6)           # south-central lot
rect(172, 110, 240, 132, GRAVEL)  # a gravel yard joined to the central road
for k in range(5):
    rect(180 + 8 * k, 114, 185 + 8 * k, 123, VEHICLE)

# Trees on the grass: canopy with a trunk.
for cx, cy in ((110, 140), (126, 150), (230, 160), (70, 8), (250, 8)):
    disk(cx, cy, 5, VEGETATION)
    rect(cx - 1, cy - 1, cx + 1, cy + 1, TRUNK)

# Anti-aliasing: road edges blended half-way with the grass beside them.
blend = tuple((a + b) // 2 for a, b in zip(ROAD, GRASS))
for y in range(H):
    for x in range(1, W - 1):
        if img[y][x] == GRASS and (img[y][x - 1] == ROAD or img[y][x + 1] == ROAD) and (x + y) % 3 == 0:
            img[y][x] = blend
# A few stray pixels of a colour no class has (a segmentation tool's "unlabelled" yellow).
for x, y in ((100, 110), (101, 110), (140, 60), (260, 150)):
    img[y][x] = (255, 255, 0)


def png(path, pixels):
    raw = b"".join(b"\x00" + bytes(c for px in row for c in px) for row in pixels)

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        f.write(chunk(b"IEND", b""))


png(os.path.join(os.path.dirname(os.path.abspath(__file__)), "campus.png"), img)
