#!/usr/bin/env python3
"""Raw-looking TacTip taps: real tap deformations moved onto a raw camera frame.

    python eval/raw_taps.py [--data data/real] [--frames N] [--light]

The shear sets (eval/layout.py) are real taps, but they are the Bristol
pipeline's *processed* frames: binarised, cropped, circle-masked. A user's
camera gives raw frames instead: grey-white pins in a dark disc, a bright
housing, LEDs and dust around it, some dimmer bluish pins. The one public raw
frame (``tactip_raw``) has no taps. This script joins the two, so that the
pipeline meets raw frames whose pins move as real taps moved them:

1. The raw frame's 331 pins (``pins_ref.csv``) are inpainted out of its
   skin (``split_pins``), and each pin's own patch above that skin is kept.
2. For each frame of ``tactip_shear_cr``, its pin centres (``pin_centres``)
   are carried to the raw frame by the similarity that takes the processed
   frame's pin disc (centre and radius of the level tap's lattice, the
   level tap being eval/run.py's ``level`` rest) onto the raw frame's.
3. At each of those places the patch of the nearest raw pin is pasted,
   sub-pixel (``render``).

The housing, LEDs, dust, the skin and the pins' own shapes and colours
(some bluish) are the camera's pixels. What it cannot show: the shading
changes of a real tap (pins under the contact tilting and dimming), and
pins a deep tap merged in the processed frame beyond splitting (then the
frame has fewer pins: its ``pins`` label says how many).

Writes ``data/real/tactip_raw_taps/`` in the layout of eval/layout.py:
``frames/*.png`` (640x480 RGB), ``labels.csv`` (the cr labels and ``pins``,
the frame's pin count, which eval/run.py scores the count against), ``set.json``
(331 pins, no rest frame: a data set without one, as the issue's real taps).
With ``--light`` every frame also gets its own light (0.6-1.0 gain, a linear
gradient of up to 25 %, sensor noise), so that a rest made from the
frames (their median, or the level tap) has another light than most frames.
Then ``eval/run.py --sets tactip_raw_taps`` scores it (the ``median`` rest
is the issue's own protocol: the pixel-wise median of the frames, no config).
Third-party pixels: ``data/`` is git-ignored, never commit the frames.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage as ndi
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run import level_tap  # noqa: E402  (eval/run.py's `level` rest rule)

PINS = 331


def pin_centres(binary: np.ndarray) -> np.ndarray:
    """Pin centres of a processed (binarised) frame.

    A 4-connected white region of 60-250 px is one pin (eval/layout.py's
    rule); a larger one (pins merged by a deep tap, or rim debris) gives one
    pin per peak of its distance transform at least 3 px deep and 7 px apart.
    """
    white = (binary > 127).astype(np.uint8)
    n, lab, stats, cents = cv2.connectedComponentsWithStats(white, connectivity=4)
    area = stats[:, cv2.CC_STAT_AREA]
    pts = [cents[i] for i in range(1, n) if 60 <= area[i] <= 250]
    big = np.isin(lab, [i for i in range(1, n) if area[i] > 250])
    if big.any():
        dist = cv2.distanceTransform(white * big.astype(np.uint8), cv2.DIST_L2, 5)
        peak = (dist == ndi.maximum_filter(dist, size=7)) & (dist >= 3.0)
        plab, k = ndi.label(peak)
        pts += list(np.array(ndi.center_of_mass(peak, plab, range(1, k + 1)))[:, ::-1]) if k else []
    return np.array(pts, dtype=float).reshape(-1, 2)


def lattice_disc(pts: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and outer radius (the 97th percentile of the pins' radii) of a pin lattice."""
    c = pts.mean(axis=0)  # a whole disc of pins: its mean is its centre
    r = np.hypot(*(pts - c).T)
    return c, float(np.percentile(r, 97))


def split_pins(raw: np.ndarray, pins: np.ndarray, pitch: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """The raw frame without its pins (the skin inpainted under a disc of 0.4
    pitch around each) and each pin's own patch above that background."""
    r = int(round(0.5 * pitch))
    under = np.zeros(raw.shape[:2], np.uint8)
    for x, y in pins:
        cv2.circle(under, (int(round(x)), int(round(y))), int(round(0.4 * pitch)), 255, -1)
    bg = cv2.inpaint(raw, under, 3, cv2.INPAINT_TELEA)
    top = raw.astype(np.float32) - bg.astype(np.float32)
    patches = []
    for x, y in pins:
        x0, y0 = int(round(x)) - r, int(round(y)) - r
        patch = np.zeros((2 * r + 1, 2 * r + 1, raw.shape[2]), np.float32)
        ys, xs = slice(max(y0, 0), min(y0 + 2 * r + 1, raw.shape[0])), slice(max(x0, 0), min(x0 + 2 * r + 1, raw.shape[1]))
        patch[ys.start - y0:ys.stop - y0, xs.start - x0:xs.stop - x0] = top[ys, xs]
        # Only this pin: the patch fades out beyond its radius.
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        patch *= np.clip((r + 0.5 - np.hypot(xx + x0 + r - x, yy + y0 + r - y)) / 1.5, 0, 1)[..., None]
        patches.append(patch)
    return bg, patches


def render(bg: np.ndarray, raw_pins: np.ndarray, patches: list[np.ndarray],
           at: np.ndarray) -> tuple[np.ndarray, int]:
    """``bg`` with a pin at each of ``at`` (raw px): the raw pin nearest to it,
    moved there sub-pixel; and how many were pasted (a patch crossing the
    frame's edge is left out)."""
    out = bg.astype(np.float32)
    top = np.zeros_like(out)
    h, w = bg.shape[:2]
    _, nearest = cKDTree(raw_pins).query(at)
    pasted = 0
    for (x, y), j in zip(at, nearest):
        patch = patches[j]
        r = patch.shape[0] // 2
        # The patch holds pin j at (r, r) + its sub-pixel offset o; put that at (x, y).
        ox, oy = raw_pins[j] - np.round(raw_pins[j])
        cx, cy = int(round(x - ox)), int(round(y - oy))
        x0, y0 = cx - r, cy - r
        if x0 < 0 or y0 < 0 or x0 + 2 * r + 1 > w or y0 + 2 * r + 1 > h:
            continue
        m = np.float32([[1, 0, x - ox - cx], [0, 1, y - oy - cy]])
        moved = cv2.warpAffine(patch, m, (2 * r + 1, 2 * r + 1), flags=cv2.INTER_LINEAR)
        region = top[y0:y0 + 2 * r + 1, x0:x0 + 2 * r + 1]
        np.maximum(region, moved, out=region)
        pasted += 1
    return np.clip(out + top, 0, 255).round().astype(np.uint8), pasted


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default="data/real")
    ap.add_argument("--frames", type=int, default=0, help="first N frames of the cr set (0: all)")
    ap.add_argument("--light", action="store_true", help="a light of its own per frame (name gets _light)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    data = Path(args.data)
    cr = data / "tactip_shear_cr"
    raw_dir = data / "tactip_raw"
    name = "tactip_raw_taps" + ("_light" if args.light else "")
    out = data / name
    for need in (cr / "labels.csv", raw_dir / "rest.png", raw_dir / "pins_ref.csv"):
        if not need.exists():
            raise SystemExit(f"raw_taps.py: {need} missing: run eval/get-data.sh first")
    labels = list(csv.DictReader(open(cr / "labels.csv", newline="")))
    level = cr / "frames" / f"{level_tap(labels)['frame']}.png"
    if args.frames:
        labels = labels[:args.frames]

    rest_p = cv2.imread(str(level), cv2.IMREAD_GRAYSCALE)  # the processed frames' lattice
    raw = cv2.imread(str(raw_dir / "rest.png"), cv2.IMREAD_COLOR)
    with open(raw_dir / "pins_ref.csv", newline="") as f:
        ref = np.array([[float(r["x"]), float(r["y"])] for r in csv.DictReader(f)])
    rest_pins = pin_centres(rest_p)
    cp, rp = lattice_disc(rest_pins)
    cr_raw, rr = lattice_disc(ref)
    s = rr / rp  # raw px per processed px
    pitch_raw = float(np.median(cKDTree(ref).query(ref, 2)[0][:, 1]))

    bg, patches = split_pins(raw, ref, pitch_raw)
    h, w = raw.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)

    if out.exists():
        shutil.rmtree(out)
    (out / "frames").mkdir(parents=True)
    rng = np.random.default_rng(args.seed)
    rows = []
    for lab in labels:
        tap = cv2.imread(str(cr / "frames" / f"{lab['frame']}.png"), cv2.IMREAD_GRAYSCALE)
        at = (pin_centres(tap) - cp) * s + cr_raw
        img, pins = render(bg, ref, patches, at)
        if args.light:
            gain = rng.uniform(0.6, 1.0)
            ang = rng.uniform(0, 2 * np.pi)
            grad = 1 + rng.uniform(0, 0.25) * ((np.cos(ang) * (xx - w / 2) + np.sin(ang) * (yy - h / 2)) / (w / 2))
            noisy = img.astype(np.float32) * (gain * grad)[..., None] + rng.normal(0, 3, img.shape)
            img = np.clip(noisy, 0, 255).round().astype(np.uint8)
        cv2.imwrite(str(out / "frames" / f"{lab['frame']}.png"), img)
        rows.append({**lab, "pins": pins})
    with open(out / "labels.csv", "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        wr.writeheader()
        wr.writerows(rows)
    meta = json.loads((cr / "set.json").read_text())
    meta.update({
        "name": name,
        "source": "eval/raw_taps.py: tactip_raw's pins placed where "
                  "tactip_shear_cr's taps put their pins (" + meta["source"] + ")",
        "size": "640x480 RGB",
        "pin_count": PINS,
        "pin_count_how": "tactip_raw's 331 reference pins, moved by each tap",
        "notes": "Raw-looking taps: the raw frame's own pixels (housing, LEDs, dust, bluish pins) "
                 "moved as the cr taps moved their pins; no rest frame." + (
                     " Each frame has a light of its own (gain 0.6-1.0, gradient up to 25 %, "
                     "noise sigma 3)." if args.light else ""),
        "frames": len(rows),
        "similarity": {"processed_centre_px": cp.round(2).tolist(), "raw_centre_px": cr_raw.round(2).tolist(),
                       "raw_px_per_processed_px": round(s, 4)},
        "rest": None,
        "pins_ref_rule": None,
    })
    (out / "set.json").write_text(json.dumps(meta, indent=2) + "\n")
    print(f"{name}: {len(rows)} frames -> {out} (scale {s:.3f}, raw disc centre "
          f"{cr_raw[0]:.1f},{cr_raw[1]:.1f}, outer pins r {rr:.1f} px)")


if __name__ == "__main__":
    main()
