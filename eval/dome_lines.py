#!/usr/bin/env python3
"""Where displacement lines meet on eval/render.py's domes, with perfect markers.

    python eval/dome_lines.py [--seed 1] [--radius-px 263] [--categories nominal edge large ...]

``dexitac``'s tracked centre is the point the markers' displacement lines
meet, in a gnomonic chart of an orthographic dome (``tactile/src/surface.rs``).
This takes the renderer's *true* pins of every contact frame without shear
and fits that point (weights ``|u|^2``, the same robust reweighting as
``tracking::radial_centre_on``), three ways:

- ``actual``: the pins as rendered, in the chart of the orthographic dome
  ``dexitac`` fits to the rest frames (apex on the optical axis; radius
  ``--radius-px``, 263 px as ``dexitac analyze -v`` reports it: "skin dome
  (radius 263 px, ...)");
- ``no_normal``: the same, with each pin's deflection towards the sphere's
  centre taken out (only its motion along the skin is left);
- ``skin``: in the renderer's own skin coordinates, where the lines of a
  press without shear meet at its centre by construction.

It prints the median error and its median radial part (from the image
centre; positive: outwards) per category, in image px (``skin``: in mm on
the skin). The gap between ``actual`` and
``no_normal`` is what the press's motion towards the camera does to the
lines (it moves the pressed pins towards the apex in the chart); the gap
between ``no_normal`` and ``skin`` is what the orthographic dome model
misses of the renderer's camera (a pinhole 5 mm behind the sphere's centre,
with barrel distortion).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import render as R  # noqa: E402

INLIER_PX, MIN_MOVE_PX = 2.0, 0.5


def meet(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Robust least-squares point nearest to the lines through q along v."""
    w0 = np.sum(v * v, 1)
    d = v / np.sqrt(np.maximum(w0, 1e-18))[:, None]
    w = w0.copy()
    c = q.mean(0)
    for _ in range(4):
        m = np.eye(2)[None] - d[:, :, None] * d[:, None, :]
        a = np.einsum("n,nij->ij", w, m)
        b = np.einsum("n,nij,nj->i", w, m, q)
        c = np.linalg.solve(a, b)
        r = np.abs((c[0] - q[:, 0]) * d[:, 1] - (c[1] - q[:, 1]) * d[:, 0])
        w = w0 / (1 + (r / INLIER_PX) ** 2)
    return c


class Chart:
    """Gnomonic chart of an orthographic dome seen along its axis at ``o``."""

    def __init__(self, o: np.ndarray, radius_px: float):
        self.o, self.r = o, radius_px

    def to(self, p: np.ndarray) -> np.ndarray:
        x = (p - self.o) / self.r
        z = np.sqrt(np.clip(1 - np.sum(x * x, -1), 1e-6, None))
        return self.o + self.r * x / z[..., None]

    def back(self, q: np.ndarray) -> np.ndarray:
        a = (q - self.o) / self.r
        return self.o + self.r * a / np.sqrt(1 + np.sum(a * a, -1))[..., None]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--frames-per-category", type=int, default=24)
    ap.add_argument("--radius-px", type=float, default=263.0, help="the dome's radius in the chart, px")
    ap.add_argument("--categories", nargs="*", default=["nominal", "harsh_light", "blur", "edge", "large", "two_colour"])
    a = ap.parse_args()
    print("| category | frames | actual px (radial) | no_normal px (radial) | skin mm |")
    print("|---|---|---|---|---|")
    for cat in a.categories:
        s = R.sensor_of(cat, a.seed)
        if s.kind != "dome":
            continue
        rest, *_ = R.pins(s, None)
        o = np.array([s.CX, s.CY])
        chart = Chart(o, a.radius_px)
        out = {k: ([], []) for k in ("actual", "no_normal", "skin")}
        for _, _, contact in R.frame_contacts(cat, s, a.seed, a.frames_per_category):
            if contact is None or np.hypot(*contact["shear"]) > 0:
                continue
            p3, q2, _, _, _, truth = R.deform(s, contact)
            out_dir = (truth - o) / max(float(np.hypot(*(truth - o))), 1e-9)
            for name, now in (("actual", s.project(p3)), ("no_normal", s.project(s.to3d(q2, 0.0)))):
                keep = R.in_frame(now) & (np.hypot(*(now - rest).T) > MIN_MOVE_PX)
                q = chart.to(rest[keep])
                e = chart.back(meet(q, chart.to(now[keep]) - q)) - truth
                out[name][0].append(math.hypot(*e))
                out[name][1].append(float(e @ out_dir))
            keep = np.hypot(*(q2 - s.q0).T) > 1e-3
            c = meet(s.q0[keep], q2[keep] - s.q0[keep])
            out["skin"][0].append(float(np.hypot(*(c - contact["c"]))))
        n = len(out["skin"][0])
        cell = lambda k: f"{np.median(out[k][0]):.2f} ({np.median(out[k][1]):+.2f})"  # noqa: E731
        print(f"| {cat} | {n} | {cell('actual')} | {cell('no_normal')} | {np.median(out['skin'][0]):.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
