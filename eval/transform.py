#!/usr/bin/env python3
"""Frames of eval/render.py under camera conditions the renderer never had.

    python eval/transform.py --frames DIR --out OUT [--scale S] [--jpeg Q] [--pad-width W]

Copies every category of ``DIR`` (from ``render.py --out DIR``) to ``OUT``
with, in this order:

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
import os
import shutil
from pathlib import Path

import cv2
import numpy as np


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
    a = ap.parse_args()
    for cat in sorted(p for p in a.frames.iterdir() if (p / "truth.csv").exists()):
        out = a.out / cat.name
        (out / "frames").mkdir(parents=True, exist_ok=True)
        left = 0
        for f in [cat / "rest.png", *sorted((cat / "frames").glob("*.png"))]:
            img, left = transform(cv2.imread(str(f), cv2.IMREAD_UNCHANGED), a.scale, a.pad_width)
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
            p[1] = f"{(x + 0.5) * a.scale - 0.5 + left:.3f}"
            p[2] = f"{(y + 0.5) * a.scale - 0.5:.3f}"
            rows.append(",".join(p))
        (out / "truth.csv").write_text("\n".join(rows) + "\n")
        shutil.copy(cat / "contacts.csv", out / "contacts.csv")


if __name__ == "__main__":
    main()
