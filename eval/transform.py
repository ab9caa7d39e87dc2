#!/usr/bin/env python3
"""Frames of eval/render.py under camera conditions the renderer never had.

    python eval/transform.py --frames DIR --out OUT [--scale S] [--jpeg Q] [--pad-width W]
        [--rotate DEG] [--barrel K] [--gamma G] [--gain G] [--motion PX]

Copies every category of ``DIR`` (from ``render.py --out DIR``) to ``OUT``
with, in this order:

- ``--rotate DEG``: rest and frames rotated by ``DEG`` degrees
  (anticlockwise in the image) about the frame's centre, the corners filled
  with dark grey (a camera mounted turned on its sensor), the truth rotated;
- ``--barrel K``: rest and frames warped by the radial lens distortion
  ``r_d = r (1 + K (r / r_max)^2)`` (``r_max`` the half-diagonal; ``K < 0``
  barrel, as a wide-angle lens), the truth mapped the same way;
- ``--motion PX``: the frames only smeared along a line of ``PX`` px
  (rounded to an odd length) at 30 degrees, as ``render_stress.py``'s
  ``motion6`` (a tap faster than the shutter: motion blur, not a PSF);
- ``--gamma G``: the frames only (not the rest) mapped by
  ``255 (v / 255)^G`` per channel (a camera whose auto exposure or gamma
  changed after the rest was taken);
- ``--gain G``: the frames only multiplied by ``G`` and clipped at 255 (over
  exposure: the pins saturate, more with ``G`` > 1);
- ``--scale S``: every frame and rest resized by ``S`` with OpenCV
  (``INTER_AREA`` down, ``INTER_LINEAR`` up), the truth centres mapped
  (pixel centres kept: ``x' = (x + 0.5) S - 0.5``): a camera of another
  resolution;
- ``--pad-width W``: the frame centred in a ``W`` px wide frame of dark grey
  (a 16:9 camera on a 4:3 sensor), the truth shifted;
- ``--jpeg Q``: written as JPEG of quality ``Q`` (a camera's MJPEG stream),
  with ``rest.png`` a link to ``rest.jpg`` so that ``render_eval.py`` runs as
  on the PNG frames.

The truth and contacts files follow. Then ``eval/render_eval.py --frames
OUT`` scores dexitac on them; the centre errors are in the new frame's
pixels.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from render_stress import after_camera  # noqa: E402


def lens_centre(w: int, h: int) -> tuple[float, float, float]:
    """The distortion's centre (the frame's) and ``r_max`` (the half-diagonal)."""
    return (w - 1) / 2, (h - 1) / 2, math.hypot(w, h) / 2


def rotation(w: int, h: int, deg: float) -> np.ndarray:
    """The 2x3 matrix of ``--rotate``: anticlockwise about the frame's centre."""
    return cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), deg, 1.0)


def lens_maps(w: int, h: int, k: float) -> tuple[np.ndarray, np.ndarray]:
    """For every output pixel, the input pixel the distortion puts there:
    the inverse of ``r_d = r (1 + k (r / r_max)^2)``, by fixed-point
    iteration (converges for |k| < 0.3)."""
    cx, cy, rmax = lens_centre(w, h)
    yd, xd = np.mgrid[0:h, 0:w].astype(np.float64)
    dx, dy = (xd - cx) / rmax, (yd - cy) / rmax
    rd = np.hypot(dx, dy)
    r = rd.copy()
    for _ in range(30):
        r = rd / (1 + k * r * r)
    s = np.where(rd > 0, r / np.maximum(rd, 1e-12), 1.0)
    return (cx + dx * s * rmax).astype(np.float32), (cy + dy * s * rmax).astype(np.float32)


def distort_point(x: float, y: float, w: int, h: int, k: float) -> tuple[float, float]:
    cx, cy, rmax = lens_centre(w, h)
    dx, dy = (x - cx) / rmax, (y - cy) / rmax
    f = 1 + k * (dx * dx + dy * dy)
    return cx + dx * f * rmax, cy + dy * f * rmax


def geometry(img: np.ndarray, a: argparse.Namespace) -> np.ndarray:
    h, w = img.shape[:2]
    if a.rotate:
        img = cv2.warpAffine(img, rotation(w, h, a.rotate), (w, h), flags=cv2.INTER_LINEAR, borderValue=(20, 20, 20))
    if a.barrel:
        mx, my = lens_maps(w, h, a.barrel)
        img = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderValue=(20, 20, 20))
    return img


def exposure(img: np.ndarray, a: argparse.Namespace) -> np.ndarray:
    """The frame-only conditions (the rest keeps the renderer's): the
    motion blur and the tone curve of ``render_stress.py``'s ``motion6`` and
    ``gamma0.6``, then the gain."""
    cond: dict = {}
    if a.motion:
        cond.update(motion_px=a.motion, motion_deg=30.0)
    if a.gamma != 1.0:
        cond["gamma"] = a.gamma
    img = after_camera(img, cond, np.random.default_rng(0))
    if a.gain != 1.0:
        img = np.clip(np.rint(img.astype(np.float64) * a.gain), 0, 255).astype(np.uint8)
    return img


def transform(img: np.ndarray, scale: float, pad_width: int | None) -> tuple[np.ndarray, int]:
    if scale != 1.0:
        interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
        img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=interp)
    left = 0
    if pad_width is not None and pad_width > img.shape[1]:
        left = (pad_width - img.shape[1]) // 2
        pad = [(0, 0), (left, pad_width - img.shape[1] - left)] + [(0, 0)] * (img.ndim - 2)
        img = np.pad(img, pad, constant_values=20)
    return img, left


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--jpeg", type=int, default=None, metavar="Q")
    ap.add_argument("--pad-width", type=int, default=None, metavar="W")
    ap.add_argument("--rotate", type=float, default=0.0, metavar="DEG")
    ap.add_argument("--barrel", type=float, default=0.0, metavar="K")
    ap.add_argument("--gamma", type=float, default=1.0, metavar="G")
    ap.add_argument("--gain", type=float, default=1.0, metavar="G")
    ap.add_argument("--motion", type=float, default=0.0, metavar="PX")
    a = ap.parse_args()
    if not (abs(a.barrel) < 0.3 and a.gamma > 0 and a.gain > 0 and a.motion >= 0):
        ap.error("need |--barrel| < 0.3, --gamma > 0, --gain > 0, --motion >= 0")
    for cat in sorted(p for p in a.frames.iterdir() if (p / "truth.csv").exists()):
        out = a.out / cat.name
        (out / "frames").mkdir(parents=True, exist_ok=True)
        left = 0
        shape = None
        for f in [cat / "rest.png", *sorted((cat / "frames").glob("*.png"))]:
            img = geometry(cv2.imread(str(f), cv2.IMREAD_UNCHANGED), a)
            shape = img.shape[:2]
            if f.name != "rest.png":
                img = exposure(img, a)
            img, left = transform(img, a.scale, a.pad_width)
            dst = out / f.relative_to(cat)
            if a.jpeg is None:
                cv2.imwrite(str(dst), img)
            else:
                cv2.imwrite(str(dst.with_suffix(".jpg")), img, [cv2.IMWRITE_JPEG_QUALITY, a.jpeg])
        if a.jpeg is not None:
            link = out / "rest.png"
            link.unlink(missing_ok=True)
            os.symlink("rest.jpg", link)
        lines = (cat / "truth.csv").read_text().splitlines()
        rows = [lines[0]]
        for line in lines[1:]:
            p = line.split(",")
            x, y = float(p[1]), float(p[2])
            if shape is not None and not math.isnan(x):
                h, w = shape
                if a.rotate:
                    x, y = rotation(w, h, a.rotate) @ np.array([x, y, 1.0])
                if a.barrel:
                    x, y = distort_point(x, y, w, h, a.barrel)
            p[1] = f"{(x + 0.5) * a.scale - 0.5 + left:.3f}"
            p[2] = f"{(y + 0.5) * a.scale - 0.5:.3f}"
            rows.append(",".join(p))
        (out / "truth.csv").write_text("\n".join(rows) + "\n")
        shutil.copy(cat / "contacts.csv", out / "contacts.csv")


if __name__ == "__main__":
    main()
