#!/usr/bin/env python3
"""How close a density-centroid contact centre can get on eval/render.py's frames.

    python eval/centre_floor.py [--seed 1] [--frames-per-category 24] [--categories ...]

For every contact frame of the renderer (same seeds as ``render.py``) it
takes the renderer's *true* pin positions, at rest and pressed, instead of
detected markers, and runs the density stages the way ``dexitac`` does by
default: a Gaussian kernel density (h = 15 px) on an 8 px grid, the ratio
to the rest density, the sensing mask where the rest density is at least
half its 90th percentile, the largest 4-connected region grown through
ratios below 0.90 from ratios below 0.80 (most cells below 0.80), and its
centroid with each cell weighted by how far its ratio lies below 0.90 (the
image-plane centroid; ``dexitac`` takes wide regions' centroids on the
skin and weights the rim's cells by their rest density).

What is left is the method's own error on this renderer, with perfect
markers: where the pressed skin's density dent lies against the truth
centre (the indenter's axis on the skin, in rest-frame pixels). Parallax
of the pressed pins, shear, the rim's clamp and the dent's asymmetry on a
dome all stay in it. Prints, per category, the median and 95th percentile
of the error and the median of its radial component (from the image
centre; negative: towards the centre). ``--area-weights`` also weights
each cell by its rest density, i.e. by the skin area it covers.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))
import render as R  # noqa: E402

H_PX, STEP_PX, THRESHOLD, EXTENT, MASK_FRACTION = 15.0, 8, 0.80, 0.90, 0.5


def kde(xy: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """Sum of Gaussians of width H_PX at the grid points (separable)."""
    ex = np.exp(-((gx[None, :] - xy[:, 0:1]) ** 2) / (2 * H_PX**2))  # (n, nx)
    ey = np.exp(-((gy[None, :] - xy[:, 1:2]) ** 2) / (2 * H_PX**2))  # (n, ny)
    return ey.T @ ex  # (ny, nx)


def positions(sensor, contact) -> tuple[np.ndarray, np.ndarray | None]:
    """The true centres of the pins inside the image, and the truth centre."""
    xy, _, _, _, truth = R.pins(sensor, contact)
    return xy[R.in_frame(xy)], truth


def centre(
    ratio: np.ndarray, mask: np.ndarray, gx: np.ndarray, gy: np.ndarray, area: np.ndarray | float = 1.0
) -> np.ndarray | None:
    low = mask & (ratio < EXTENT)
    labels, n = ndimage.label(low)
    if n == 0:
        return None
    seeds = ndimage.sum(mask & (ratio < THRESHOLD), labels, index=np.arange(1, n + 1))
    if seeds.max() == 0:
        return None
    region = labels == (1 + int(np.argmax(seeds)))
    w = np.where(region, EXTENT - ratio, 0.0) * area
    return np.array([(w.sum(0) * gx).sum(), (w.sum(1) * gy).sum()]) / w.sum()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--frames-per-category", type=int, default=24)
    ap.add_argument("--categories", nargs="*", default=[c for c in R.CATEGORIES if c != "no_contact"])
    ap.add_argument(
        "--area-weights",
        action="store_true",
        help="weight each cell also by its rest density (the skin area its pixels cover, pins being "
        "evenly spread on the skin): the centroid on the skin rather than in the image",
    )
    a = ap.parse_args()
    gx = np.arange(0, R.W, STEP_PX) + (STEP_PX - 1) / 2
    gy = np.arange(0, R.H, STEP_PX) + (STEP_PX - 1) / 2
    print("| category | contact frames | centred | error median px | p95 px | radial median px |")
    print("|---|---|---|---|---|---|")
    for cat in a.categories:
        sensor = R.sensor_of(cat, a.seed)
        rest_xy, _ = positions(sensor, None)
        rest = kde(rest_xy, gx, gy)
        mask = rest >= MASK_FRACTION * np.quantile(rest[rest > 0], 0.9)
        mid = np.array([R.W, R.H]) / 2
        err, radial, n = [], [], 0
        for _, _, contact in R.frame_contacts(cat, sensor, a.seed, a.frames_per_category):
            if contact is None:
                continue
            n += 1
            xy, truth = positions(sensor, contact)
            c = centre(kde(xy, gx, gy) / np.maximum(rest, 1e-12), mask, gx, gy, rest if a.area_weights else 1.0)
            if c is None:
                continue
            e = c - truth
            out = (truth - mid) / max(float(np.linalg.norm(truth - mid)), 1e-9)
            err.append(float(np.hypot(*e)))
            radial.append(float(e @ out))
        if not err:
            print(f"| {cat} | {n} | 0 | – | – | – |")
            continue
        print(
            f"| {cat} | {n} | {len(err)} | {np.median(err):.2f} | {np.percentile(err, 95):.2f} | "
            f"{np.median(radial):+.2f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
