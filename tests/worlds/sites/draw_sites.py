#!/usr/bin/env python3
"""Draws the two self-made "real site" class rasters `spomp world import` is tested on.

Each has what class maps exported from a site survey have: the site's own class names (the
class tables beside them: a YAML list of names and colours, and a JSON one with hex colours), a
transparent margin outside the surveyed area, a white text label and scale bar printed on the
map, anti-aliased (blended) class edges, and dead-end pockets (grass wedges narrowing between
buildings and bushes). 0.5 m per pixel, north up; cars 2 m x 4.5 m (4 x 9 px) in clusters on
parking lots. Standard library only; run it from anywhere to regenerate the PNGs next to this
script (byte-for-byte reproducible).

- yard.png (260 x 200 px, 130 m x 100 m), yard-classes.yaml: an industrial yard.
- hill.png (240 x 220 px, 120 m x 110 m), hill-classes.json: a campus on a hill side.
"""

import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
CLEAR = None  # transparent (alpha 0)

# 5 x 7 glyphs for the labels.
FONT = {
    "A": ["01110", "10001", "10001", "11111", "10001", "10001", "10001"],
    "D": ["11110", "10001", "10001", "10001", "10001", "10001", "11110"],
    "H": ["10001", "10001", "10001", "11111", "10001", "10001", "10001"],
    "I": ["01110", "00100", "00100", "00100", "00100", "00100", "01110"],
    "L": ["10000", "10000", "10000", "10000", "10000", "10000", "11111"],
    "M": ["10001", "11011", "10101", "10101", "10001", "10001", "10001"],
    "N": ["10001", "11001", "10101", "10011", "10001", "10001", "10001"],
    "R": ["11110", "10001", "10001", "11110", "10100", "10010", "10001"],
    "Y": ["10001", "10001", "01010", "00100", "00100", "00100", "00100"],
    "0": ["01110", "10001", "10011", "10101", "11001", "10001", "01110"],
    "2": ["01110", "10001", "00001", "00010", "00100", "01000", "11111"],
    "5": ["11111", "10000", "11110", "00001", "00001", "10001", "01110"],
    " ": ["00000"] * 7,
}


class Raster:
    def __init__(self, w, h, fill):
        self.w, self.h = w, h
        self.px = [[fill for _ in range(w)] for _ in range(h)]

    def rect(self, x0, y0, x1, y1, c):
        """Pixels x0 <= x < x1, y0 <= y < y1 (image coordinates, y down)."""
        for y in range(max(0, y0), min(self.h, y1)):
            for x in range(max(0, x0), min(self.w, x1)):
                self.px[y][x] = c

    def disk(self, cx, cy, r, c):
        for y in range(cy - r, cy + r + 1):
            for x in range(cx - r, cx + r + 1):
                if 0 <= x < self.w and 0 <= y < self.h and (x - cx) ** 2 + (y - cy) ** 2 <= r * r:
                    self.px[y][x] = c

    def triangle(self, a, b, c, colour):
        (ax, ay), (bx, by), (cx, cy) = a, b, c
        def side(px, py, x0, y0, x1, y1):
            return (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0)
        for y in range(min(ay, by, cy), max(ay, by, cy) + 1):
            for x in range(min(ax, bx, cx), max(ax, bx, cx) + 1):
                s = [side(x + 0.5, y + 0.5, *a, *b), side(x + 0.5, y + 0.5, *b, *c), side(x + 0.5, y + 0.5, *c, *a)]
                if (all(v >= 0 for v in s) or all(v <= 0 for v in s)) and 0 <= x < self.w and 0 <= y < self.h:
                    self.px[y][x] = colour

    def lot(self, x0, y0, cars, rows, road, car):
        """A parking lot of road surface with rows of cars (4 x 9 px), 6 px apart."""
        self.rect(x0, y0, x0 + 6 * cars + 6, y0 + 14 * rows + 6, road)
        for r in range(rows):
            for k in range(cars):
                self.rect(x0 + 4 + 6 * k, y0 + 3 + 14 * r, x0 + 8 + 6 * k, y0 + 12 + 14 * r, car)

    def text(self, x0, y0, s, scale, colour):
        for i, ch in enumerate(s):
            for gy, row in enumerate(FONT[ch]):
                for gx, bit in enumerate(row):
                    if bit == "1":
                        x, y = x0 + (6 * i + gx) * scale, y0 + gy * scale
                        self.rect(x, y, x + scale, y + scale, colour)

    def antialias(self):
        """Blends every opaque pixel on a class edge with its opaque 3 x 3 neighbours, as a
        resampled segmentation export does; interiors keep their exact colours."""
        out = [row[:] for row in self.px]
        for y in range(self.h):
            for x in range(self.w):
                if self.px[y][x] is CLEAR:
                    continue
                near = [self.px[j][i] for j in range(max(0, y - 1), min(self.h, y + 2))
                        for i in range(max(0, x - 1), min(self.w, x + 2)) if self.px[j][i] is not CLEAR]
                if any(n != self.px[y][x] for n in near):
                    out[y][x] = tuple(sum(n[k] for n in near) // len(near) for k in range(3))
        self.px = out

    def write(self, name):
        raw = b"".join(
            b"\x00" + b"".join(bytes((0, 0, 0, 0)) if p is CLEAR else bytes((*p, 255)) for p in row)
            for row in self.px)

        def chunk(kind, data):
            body = kind + data
            return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)

        with open(os.path.join(HERE, name), "wb") as f:
            f.write(b"\x89PNG\r\n\x1a\n")
            f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", self.w, self.h, 8, 6, 0, 0, 0)))
            f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
            f.write(chunk(b"IEND", b""))


WHITE, BLACK = (255, 255, 255), (0, 0, 0)


def yard():
    # yard-classes.yaml colours.
    road, veg, bldg, grass = (128, 64, 128), (107, 142, 35), (70, 70, 70), (152, 251, 152)
    car, gravel, water = (0, 0, 142), (190, 153, 153), (60, 110, 220)
    r = Raster(260, 200, grass)
    # Roads 12 m wide: one east-west near the south, two north-south.
    r.rect(0, 150, 260, 174, road)
    r.rect(30, 0, 54, 200, road)
    r.rect(170, 0, 194, 174, road)
    r.rect(54, 60, 170, 80, road)  # a cross street
    # Buildings, a gravel yard, bushes, a pond.
    r.rect(70, 90, 130, 140, bldg)
    r.rect(200, 90, 250, 140, bldg)
    r.rect(70, 10, 120, 50, gravel)
    r.rect(130, 10, 160, 50, bldg)
    r.rect(200, 20, 240, 60, veg)
    r.disk(150, 115, 10, water)
    # Dead-end pockets: grass wedges narrowing between a building and bushes.
    r.triangle((130, 90), (160, 90), (130, 140), veg)
    r.triangle((130, 140), (165, 140), (165, 100), veg)
    r.rect(56, 92, 68, 140, veg)
    r.triangle((250, 90), (260, 90), (260, 140), veg)
    # Vehicle clusters on lots opening onto the roads.
    r.lot(56, 142, 4, 1, road, car)     # 1 row of 4 next to the south road
    r.lot(196, 176, 5, 1, road, car)    # south of the road
    r.lot(74, 14, 3, 2, gravel, car)    # in the gravel yard
    r.lot(2, 100, 3, 1, road, car)      # west of the west road
    r.lot(120, 178, 3, 1, road, car)
    r.lot(196, 64, 3, 1, road, car)
    r.antialias()
    # The surveyed area: a transparent margin along the north edge and a cut north-east corner.
    r.rect(0, 0, 260, 6, CLEAR)
    r.triangle((200, 0), (260, 0), (260, 50), CLEAR)
    # A label (white, printed on the margin and the bushes) and a scale bar on the grass.
    r.text(204, 2, "YARD", 2, WHITE)
    r.rect(206, 186, 246, 190, WHITE)
    r.rect(206, 184, 208, 192, BLACK)
    r.rect(244, 184, 246, 192, BLACK)
    r.text(214, 192, "20M", 1, WHITE)
    r.write("yard.png")


def hill():
    # hill-classes.json colours.
    road, veg, bldg, grass = (140, 70, 130), (90, 130, 40), (60, 60, 80), (160, 240, 150)
    car, path, lot_ = (10, 20, 150), (200, 160, 140), (120, 90, 120)
    r = Raster(240, 220, grass)
    # A loop road and spurs.
    r.rect(20, 180, 220, 200, road)
    r.rect(20, 20, 40, 200, road)
    r.rect(200, 60, 220, 200, road)
    r.rect(20, 20, 160, 40, road)
    r.rect(110, 40, 126, 180, path)  # a gravel footpath up the hill
    # Buildings with bushes around, forming pockets.
    r.rect(50, 60, 100, 110, bldg)
    r.rect(140, 70, 190, 120, bldg)
    r.rect(50, 130, 90, 170, bldg)
    r.triangle((90, 130), (108, 130), (90, 170), veg)
    r.triangle((126, 120), (140, 70), (140, 120), veg)
    r.rect(140, 130, 190, 150, veg)
    r.disk(170, 40, 12, veg)
    # Parking lots.
    r.lot(42, 42, 5, 1, lot_, car)
    r.lot(150, 152, 4, 1, lot_, car)
    r.lot(42, 112, 2, 1, lot_, car)
    r.lot(128, 42, 3, 1, lot_, car)
    r.lot(160, 200, 5, 1, lot_, car)
    r.antialias()
    # The survey did not cover the west strip or the south-east corner.
    r.rect(0, 0, 14, 220, CLEAR)
    r.triangle((180, 220), (240, 220), (240, 170), CLEAR)
    r.rect(0, 214, 240, 220, CLEAR)
    # A white label across the margin and the road, a scale bar on the grass.
    r.text(2, 4, "HILL", 2, WHITE)
    r.rect(150, 6, 190, 10, WHITE)
    r.text(160, 12, "20M", 1, WHITE)
    r.write("hill.png")


yard()
hill()
