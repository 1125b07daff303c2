#!/usr/bin/env python3
"""Writes molds/surfaces/hills.png: the height map of molds/heightmap-hills.toml.

Two Gaussian hills and a low ripple over 64 x 64 mm, 256 x 256 pixels,
16-bit grey: black is 0 mm, white 4 mm (the spec's z_min and z_max).
Made for moirecast and dedicated to the public domain (CC0). Standard
library only, so that it runs anywhere: `python3 scripts/make-hills.py`.
"""
import math
import struct
import sys
import zlib

SIZE_MM, PIXELS, Z_MAX = 64.0, 256, 4.0


def height(x, y):
    """mm, at x, y mm from the centre (y up)."""
    hill = 2.5 * math.exp(-((x - 6) ** 2 + (y + 4) ** 2) / (2 * 14.0**2))
    knoll = 1.2 * math.exp(-((x + 12) ** 2 + (y - 10) ** 2) / (2 * 9.0**2))
    ripple = 0.3 * math.sin(x / 6.0) * math.sin(y / 8.0)
    return 0.4 + hill + knoll + ripple


def png16(path, width, height_px, value):
    raw = bytearray()
    for j in range(height_px):
        raw.append(0)  # no filter
        for i in range(width):
            raw += struct.pack(">H", value(i, j))

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", width, height_px, 16, 0, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header))
        f.write(chunk(b"IDAT", zlib.compress(bytes(raw), 9)) + chunk(b"IEND", b""))


def pixel(i, j):
    step = SIZE_MM / PIXELS
    x = -SIZE_MM / 2 + (i + 0.5) * step
    y = SIZE_MM / 2 - (j + 0.5) * step
    return round(min(max(height(x, y) / Z_MAX, 0.0), 1.0) * 65535)


if __name__ == "__main__":
    png16(sys.argv[1] if len(sys.argv) > 1 else "molds/surfaces/hills.png", PIXELS, PIXELS, pixel)
