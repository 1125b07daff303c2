#!/usr/bin/env python3
"""A picture of a mold's two halves, pulled apart: a small z-buffer
rasteriser over the written STLs (numpy and trimesh from the test venv).

    .venv/bin/python scripts/mold-picture.py OUT_DIR docs/mold-saddle-horse.png

OUT_DIR is what `moirecast mold` wrote. The top half is turned over beside
the bottom half, so both cavities face the viewer.
"""
import sys
import zlib
import struct

import numpy as np
import trimesh


def rotation(yaw_deg, pitch_deg):
    """World to camera: turn about z by yaw, then tip about x by pitch."""
    y, p = np.radians(yaw_deg), np.radians(pitch_deg)
    rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    return rx @ rz


def rasterise(tris, colours, size, scale, offset):
    """Flat-shaded triangles (n, 3, 3) in camera space (x right, y up,
    z towards the viewer) into an RGB image; nearest wins."""
    w, h = size
    depth = np.full((h, w), -np.inf)
    image = np.full((h, w, 3), 255.0)
    px = (tris[:, :, :2] * scale + offset)
    for t, (p, c) in enumerate(zip(px, colours)):
        lo = np.floor(p.min(axis=0)).astype(int)
        hi = np.ceil(p.max(axis=0)).astype(int)
        lo = np.maximum(lo, 0)
        hi = np.minimum(hi, [w - 1, h - 1])
        if (hi < lo).any():
            continue
        xs, ys = np.meshgrid(np.arange(lo[0], hi[0] + 1) + 0.5, np.arange(lo[1], hi[1] + 1) + 0.5)
        (x0, y0), (x1, y1), (x2, y2) = p
        den = (y1 - y2) * (x0 - x2) + (x2 - x1) * (y0 - y2)
        if abs(den) < 1e-12:
            continue
        a = ((y1 - y2) * (xs - x2) + (x2 - x1) * (ys - y2)) / den
        b = ((y2 - y0) * (xs - x2) + (x0 - x2) * (ys - y2)) / den
        g = 1 - a - b
        inside = (a >= 0) & (b >= 0) & (g >= 0)
        if not inside.any():
            continue
        z = a * tris[t, 0, 2] + b * tris[t, 1, 2] + g * tris[t, 2, 2]
        iy = (ys - 0.5).astype(int)
        ix = (xs - 0.5).astype(int)
        closer = inside & (z > depth[iy, ix])
        depth[iy[closer], ix[closer]] = z[closer]
        image[iy[closer], ix[closer]] = c
    return np.flipud(image)


def png(path, rgb):
    """A minimal PNG writer (no extra dependency)."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + row.tobytes() for row in rgb.astype(np.uint8))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        f.write(chunk(b"IEND", b""))


def main(out_dir, picture, size=(1200, 560)):
    bottom = trimesh.load(f"{out_dir}/mold-bottom.stl")
    top = trimesh.load(f"{out_dir}/mold-top.stl")
    # the top half turned over (about x) and set beside the bottom half
    flip = np.diag([1.0, -1.0, -1.0])
    top_v = top.vertices @ flip.T
    width = bottom.bounds[1][0] - bottom.bounds[0][0]
    top_v[:, 0] += width * 1.15
    top_v[:, 2] += bottom.bounds[1][2] - top_v[:, 2].max()
    parts = [(bottom.vertices, bottom.faces, np.array([236, 176, 92])), (top_v, top.faces, np.array([120, 170, 220]))]
    rot = rotation(-20, -55)
    light = np.array([-0.4, 0.5, 1.0])
    light /= np.linalg.norm(light)
    tris, colours = [], []
    for verts, faces, base in parts:
        cam = verts @ rot.T
        t = cam[faces]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
        keep = n[:, 2] > 0
        shade = 0.35 + 0.65 * np.clip(n[keep] @ light, 0, 1)
        tris.append(t[keep])
        colours.append(base[None, :] * shade[:, None])
    tris = np.concatenate(tris)
    colours = np.concatenate(colours)
    lo, hi = tris.reshape(-1, 3).min(axis=0), tris.reshape(-1, 3).max(axis=0)
    scale = 0.92 * min(size[0] / (hi[0] - lo[0]), size[1] / (hi[1] - lo[1]))
    offset = np.array(size) / 2 - scale * (lo[:2] + hi[:2]) / 2
    png(picture, rasterise(tris, colours, size, scale, offset))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
