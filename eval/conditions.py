#!/usr/bin/env python3
"""dexitac on real taps under light and focus the frames never had.

    python eval/conditions.py --dexitac target/release/dexitac [--sets A B ...]
        [--conditions A B ...] [--data data/real] [--out eval/results] [--date TAG]

The TacTip shear sets (eval/layout.py) are re-rendered under each condition
below, the frames only: the rest stays the undegraded ``level`` rest that
eval/run.py makes (data/real/<set>/level_rest.png; run that first), as when
the light changes after calibration. ``dexitac analyze --rest level_rest.png``
(no config) runs on every condition, and the numbers are eval/run.py's own
(markers against the pin count, contact frames, leave-one-out R^2 of the
contact centre on tilt and depth, time per frame).

Conditions (seeded noise; grey levels of the 0/255 processed frames):

- ``none``: the frames as they are;
- ``dim3``: a third of the light;
- ``vignette_gradient``: light falling to 0.45 at the corners (1 - 0.55 r^2,
  r = 1 at the corner) times a left-to-right gradient of 30 %;
- ``blur2.5``: Gaussian blur, sigma 2.5 px;
- ``blur1.8_noise6``: blur 1.8 px and Gaussian noise of 6 grey levels;
- ``harsh``: blur 1 px, a third of the light, the vignetting and gradient
  above, an offset of 20 and noise of 4;

and what a camera's driver does to a frame (``render_stress.after_camera``):

- ``jpeg60``: JPEG at quality 60;
- ``motion6``: a linear motion blur of 6 px at 30 degrees;
- ``gamma0.6``: the tone curve ``255 (v / 255)^0.6``;
- ``shift2``: the whole frame moved by (2, -1) px (whole pixels: no
  resampling);
- ``hot_pixels``: 0.1 % of the pixels stuck at 255 and 0.1 % at 0.

The degraded frames and dexitac's CSVs go to a temporary folder and are
deleted. Writes <out>/<date>-conditions.md.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import platform
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import run as R  # noqa: E402
from render_stress import after_camera  # noqa: E402

SETS = ["tactip_shear_cr", "tactip_shear_franka"]


def vignette(shape: tuple[int, int], v: float) -> np.ndarray:
    h, w = shape
    y, x = np.mgrid[0:h, 0:w]
    r = np.hypot(x - w / 2, y - h / 2) / np.hypot(w / 2, h / 2)
    return 1 - v * r**2


def gradient(shape: tuple[int, int], g: float) -> np.ndarray:
    h, w = shape
    return np.broadcast_to((1 - g / 2 + g * np.arange(w) / w)[None, :], (h, w))


def light(im: np.ndarray) -> np.ndarray:
    return vignette(im.shape, 0.55) * gradient(im.shape, 0.3)


def driver(cond: dict):
    """A condition of ``render_stress.after_camera`` on a float frame."""

    def apply(im: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        u8 = np.clip(np.round(im), 0, 255).astype(np.uint8)
        return after_camera(u8, cond, rng).astype(np.float64)

    return apply


CONDITIONS = {
    "none": lambda im, rng: im,
    "dim3": lambda im, rng: im / 3.0,
    "vignette_gradient": lambda im, rng: im * light(im),
    "blur2.5": lambda im, rng: cv2.GaussianBlur(im, (0, 0), 2.5),
    "blur1.8_noise6": lambda im, rng: cv2.GaussianBlur(im, (0, 0), 1.8) + rng.normal(0, 6, im.shape),
    "harsh": lambda im, rng: cv2.GaussianBlur(im, (0, 0), 1.0) / 3.0 * light(im) + 20
    + rng.normal(0, 4, im.shape),
    "jpeg60": driver(dict(jpeg=60)),
    "motion6": driver(dict(motion_px=6.0, motion_deg=30.0)),
    "gamma0.6": driver(dict(gamma=0.6)),
    "shift2": driver(dict(shift_px=(2.0, -1.0))),
    "hot_pixels": driver(dict(hot=0.001)),
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dexitac", required=True)
    ap.add_argument("--sets", nargs="*", default=SETS)
    ap.add_argument("--conditions", nargs="*", default=list(CONDITIONS), choices=list(CONDITIONS))
    ap.add_argument("--data", default="data/real")
    ap.add_argument("--out", default="eval/results")
    ap.add_argument("--date", default=dt.date.today().isoformat())
    a = ap.parse_args()
    data, out = Path(a.data), Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = [
        f"# dexitac on real taps under new light and focus ({a.date})",
        "",
        f"`{' '.join(sys.argv)}` on {platform.node()}, {platform.processor() or platform.machine()}; "
        "rest: the undegraded `level_rest.png`, no config.",
        "",
        "| set | condition | frames | markers median [min–max] / pins | ±1 % | contact frames | R² x | R² y | ms/frame median |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name in a.sets:
        d = data / name
        rest = d / "level_rest.png"
        if not rest.exists():
            print(f"{name}: no {rest}; run eval/run.py first", file=sys.stderr)
            return 1
        meta = json.loads((d / "set.json").read_text())
        labels = R.read_csv(d / "labels.csv")
        for cond in a.conditions:
            f = CONDITIONS[cond]
            rng = np.random.default_rng(0)
            with tempfile.TemporaryDirectory() as tmp:
                frames = Path(tmp) / "frames"
                frames.mkdir()
                for p in sorted((d / "frames").glob("*.png")):
                    im = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE).astype(np.float64)
                    cv2.imwrite(str(frames / p.name), np.clip(np.round(f(im, rng)), 0, 255).astype(np.uint8))
                rows, wall, note = R.run_dexitac(a.dexitac, Path(tmp), rest, Path(tmp), cond, None)
            if note:
                print(f"{name} {cond}: {note}", file=sys.stderr)
            m = R.metrics(rows, labels, meta, wall)
            fmt = lambda k, p="{:.2f}": p.format(m[k]) if k in m else "–"  # noqa: E731
            lines.append(
                f"| {name} | {cond} | {m.get('frames', 0)} | {m.get('n_med', 0):.0f} "
                f"[{m.get('n_min', 0):.0f}–{m.get('n_max', 0):.0f}] / {meta['pin_count']} | "
                f"{m.get('in1', 0):.0%} | {m.get('contact', 0):.0%} | {fmt('r2x')} | {fmt('r2y')} | "
                f"{fmt('t_med')} |"
            )
            print(lines[-1], flush=True)
    (out / f"{a.date}-conditions.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / (a.date + '-conditions.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
