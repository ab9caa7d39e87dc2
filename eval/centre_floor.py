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

With ``--dexitac BIN --frames DIR`` (DIR from ``render.py --out DIR``, same
``--seed`` and ``--frames-per-category``) it also runs dexitac's own stages
on those true places: it writes each frame's true pins in the format of
``dexitac analyze --field-out`` and runs ``dexitac analyze --field-in`` on
them (the rest calibrated from DIR's rest frame, as for the frames
themselves). Those columns are what dexitac's field, density, region and
centre make of perfect markers, in every way it has (tracked centres, the
skin's chart, the rim's weights).

What is left is the method's own error on this renderer, with perfect
markers: where the pressed skin's density dent lies against the truth
centre (the indenter's axis on the skin, in rest-frame pixels). Parallax
of the pressed pins, shear, the rim's clamp and the dent's asymmetry on a
dome all stay in it. Prints, per category, the median and 95th percentile
of the error and the median of its radial component (from the image
centre; negative: towards the centre). ``--area-weights`` also weights
each cell by its rest density, i.e. by the skin area it covers.

Two options take one physical effect out of the true pins, to measure its
share of the error:

- ``--no-parallax``: each pressed pin is seen where it would be at its rest
  depth (its place on the skin unchanged, not nearer the camera);
- ``--no-shear``: a sheared contact is pressed where its indenter ends up,
  without the tangential shear (the truth centre stays where it was).

``--on-skin`` takes the first columns' density, region and centroid on the
skin instead of in the image: in the renderer's skin coordinates (mm), the
pins' image places mapped there through the rest pins (as a calibration
would map them; a pressed pin's parallax stays in its image place), with
the kernel and grid step of ``H_PX`` and ``STEP_PX`` at the image's scale
where the skin faces the camera; the centroid is then seen in the image as
the rest frame shows it.
"""

from __future__ import annotations

import argparse
import csv
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator

sys.path.insert(0, str(Path(__file__).resolve().parent))
import render as R  # noqa: E402

H_PX, STEP_PX, THRESHOLD, EXTENT, MASK_FRACTION = 15.0, 8, 0.80, 0.90, 0.5


def kde(xy: np.ndarray, gx: np.ndarray, gy: np.ndarray, h: float = H_PX) -> np.ndarray:
    """Sum of Gaussians of width ``h`` (H_PX) at the grid points (separable)."""
    ex = np.exp(-((gx[None, :] - xy[:, 0:1]) ** 2) / (2 * h**2))  # (n, nx)
    ey = np.exp(-((gy[None, :] - xy[:, 1:2]) ** 2) / (2 * h**2))  # (n, ny)
    return ey.T @ ex  # (ny, nx)


class Skin:
    """The grid and kernel of ``--on-skin`` for ``sensor``, whose pins
    ``rest_q`` (skin mm) are seen at ``rest_xy`` (image px) at rest."""

    def __init__(self, sensor, rest_xy: np.ndarray, rest_q: np.ndarray):
        at = sensor.project(sensor.to3d(np.array([[0.0, 0.0], [0.1, 0.0]]), 0.0))
        px_per_mm = float(np.hypot(*(at[1] - at[0]))) / 0.1
        self.h, step = H_PX / px_per_mm, STEP_PX / px_per_mm
        lo, hi = rest_q.min(0) - 3 * self.h, rest_q.max(0) + 3 * self.h
        self.gx, self.gy = np.arange(lo[0], hi[0], step), np.arange(lo[1], hi[1], step)
        self.linear = LinearNDInterpolator(rest_xy, rest_q)
        self.nearest = NearestNDInterpolator(rest_xy, rest_q)
        self.sensor = sensor

    def density(self, xy: np.ndarray) -> np.ndarray:
        """The density on the skin of pins seen at ``xy`` (image px)."""
        q = self.linear(xy)
        off = ~np.isfinite(q[:, 0])
        q[off] = self.nearest(xy[off])
        return kde(q, self.gx, self.gy, self.h)

    def to_image(self, q: np.ndarray) -> np.ndarray:
        """Skin point ``q`` as the rest frame shows it."""
        return self.sensor.project(self.sensor.to3d(q[None, :], 0.0))[0]


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


def pressed_pins(sensor, contact: dict | None, parallax: bool = True, shear: bool = True):
    """The pins' image places under ``contact`` and the truth centre
    (``render.pins``), optionally without the pressed pins' parallax or
    without the contact's shear (see the module doc)."""
    if contact is not None and not shear:
        moved = sensor.rim_factor(contact["c"][None, :])[0] * contact["shear"]
        contact = dict(contact, c=contact["c"] + moved, shear=np.zeros(2))
    if parallax:
        xy, _, _, _, truth = R.pins(sensor, contact)
        return xy, truth
    _, q2, _, _, _, truth = R.deform(sensor, contact)
    return sensor.project(sensor.to3d(q2, 0.0)), truth


def write_field(path: Path, rest_xy: np.ndarray, xy: np.ndarray) -> None:
    """The true pins as ``dexitac analyze --field-in`` reads them: per pin in
    the rest frame, its rest place and its place (empty when out of view)."""
    seen = R.in_frame(xy)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["rest_x", "rest_y", "x", "y"])
        for k in np.flatnonzero(R.in_frame(rest_xy)):
            at = [f"{v:.4f}" for v in xy[k]] if seen[k] else ["", ""]
            w.writerow([f"{rest_xy[k, 0]:.4f}", f"{rest_xy[k, 1]:.4f}", *at])


def dexitac_centres(dexitac: str, frames: Path, cat: str, fields: Path) -> dict[str, tuple[float, float]]:
    """dexitac's contact centre per frame of ``frames/cat`` on the fields in ``fields``."""
    out = fields / "pred.csv"
    d = frames / cat
    run = subprocess.run(
        [dexitac, "-qq", "analyze", "--rest", str(d / "rest.png"), "--field-in", str(fields), "--out", str(out), str(d / "frames")],
        capture_output=True,
        text=True,
    )
    if run.returncode != 0:
        raise SystemExit(f"dexitac analyze --field-in on {cat} failed:\n{run.stderr}")
    with open(out, newline="") as f:
        return {r["frame"]: (float(r["cx"]), float(r["cy"])) for r in csv.DictReader(f)}


def scored(c: np.ndarray, truth: np.ndarray, err: list[float], radial: list[float]) -> None:
    """Appends centre ``c``'s error against ``truth`` and its radial part
    (from the image centre; negative: towards it)."""
    mid = np.array([R.W, R.H]) / 2
    e = c - truth
    out = (truth - mid) / max(float(np.linalg.norm(truth - mid)), 1e-9)
    err.append(float(np.hypot(*e)))
    radial.append(float(e @ out))


def stats(err: list[float], radial: list[float]) -> str:
    if not err:
        return "– | – | –"
    return f"{np.median(err):.2f} | {np.percentile(err, 95):.2f} | {np.median(radial):+.2f}"


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
    ap.add_argument("--no-parallax", action="store_true", help="pressed pins seen at their rest depth")
    ap.add_argument("--no-shear", action="store_true", help="sheared contacts pressed without the shear")
    ap.add_argument("--on-skin", action="store_true", help="the first columns' density and centroid on the skin")
    ap.add_argument("--dexitac", help="dexitac binary: also run its own stages on the true places")
    ap.add_argument("--frames", type=Path, help="render.py's output for --dexitac (same seed and frame count)")
    a = ap.parse_args()
    if (a.dexitac is None) != (a.frames is None):
        ap.error("--dexitac and --frames go together")
    if a.on_skin and a.area_weights:
        ap.error("--on-skin takes the centroid on the skin already: no --area-weights with it")
    gx = np.arange(0, R.W, STEP_PX) + (STEP_PX - 1) / 2
    gy = np.arange(0, R.H, STEP_PX) + (STEP_PX - 1) / 2
    head = "| category | contact frames | centred | error median px | p95 px | radial median px |"
    if a.dexitac:
        head += " dexitac: centred | median px | p95 px | radial median px | false contacts |"
    print(head)
    print("|---" * (head.count("|") - 1) + "|")
    for cat in a.categories:
        sensor = R.sensor_of(cat, a.seed)
        # Every pin at rest (the fields), and those inside the image (the
        # density here).
        all_rest = R.pins(sensor, None)[0]
        seen = R.in_frame(all_rest)
        skin = Skin(sensor, all_rest[seen], sensor.q0[seen]) if a.on_skin else None
        rest = skin.density(all_rest[seen]) if skin else kde(all_rest[seen], gx, gy)
        mask = rest >= MASK_FRACTION * np.quantile(rest[rest > 0], 0.9)
        err, radial, n = [], [], 0
        truths: dict[str, np.ndarray | None] = {}
        tmp = tempfile.TemporaryDirectory() if a.dexitac else None
        for i, _, contact in R.frame_contacts(cat, sensor, a.seed, a.frames_per_category):
            all_xy, truth = pressed_pins(sensor, contact, not a.no_parallax, not a.no_shear)
            if tmp is not None:
                write_field(Path(tmp.name) / f"{i:04d}.csv", all_rest, all_xy)
            truths[f"{i:04d}"] = truth
            if contact is None:
                continue
            n += 1
            xy = all_xy[R.in_frame(all_xy)]
            if skin:
                c = centre(skin.density(xy) / np.maximum(rest, 1e-12), mask, skin.gx, skin.gy)
                c = None if c is None else skin.to_image(c)
            else:
                c = centre(kde(xy, gx, gy) / np.maximum(rest, 1e-12), mask, gx, gy, rest if a.area_weights else 1.0)
            if c is not None:
                scored(c, truth, err, radial)
        row = f"| {cat} | {n} | {len(err)} | {stats(err, radial)} |"
        if tmp is not None:
            got = dexitac_centres(a.dexitac, a.frames, cat, Path(tmp.name))
            d_err, d_radial, false = [], [], 0
            for name, truth in truths.items():
                cx, cy = got.get(name, (math.nan, math.nan))
                if truth is None:
                    false += int(math.isfinite(cx))
                    continue
                if math.isfinite(cx):
                    scored(np.array([cx, cy]), truth, d_err, d_radial)
            row += f" {len(d_err)} | {stats(d_err, d_radial)} | {false} |"
            tmp.cleanup()
        print(row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
