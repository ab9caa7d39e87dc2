#!/usr/bin/env python3
"""dexitac on eval/render.py's dome under conditions its categories never have.

    python eval/render_stress.py --dexitac PATH [--frames-per-condition 12] [--seed 1]
        [--conditions A B ...] [--out eval/results] [--date TAG]

Every condition renders, on the dome of ``render.py`` (955 pins), half its
frames without contact and half with a contact drawn as in the ``nominal``
category, all under the condition's light, PSF and noise; the rest frame
stays the nominal one (rendered once, as ``render.py`` does), as when the
light or focus changes after calibration. ``dexitac analyze --rest`` (no
config) runs on each condition's frames, and ``eval/render_eval.py`` scores
them: the table has its columns, one row per condition (markers within ±1 %
of the pins in the image, false contacts on the frames without contact,
contacts found, centre error median and p95, time).

Conditions (``render.py``'s ``NOMINAL`` with):

- ``blur3``: PSF sigma 3 px (the issue's upper end; the ``blur`` category
  draws 1.8-2.8);
- ``sharp``: PSF 0.6 px, sharper than the rest (1 px);
- ``dim_blur``: a third of the light, vignetting to 0.55, a 30 % gradient,
  3 electrons per grey level, read noise 2.5, PSF 2.5 px;
- ``bright``: 2.5x the light (pins clip at 255, with wide flat tops);
- ``bright_blur``: 2x the light and PSF 2.2 px;
- ``noisy``: 2 electrons per grey level, read noise 6;
- ``dark_corners``: vignetting to 0.3 at the corners;
- ``leds_off``: the housing LEDs off and a tenth of the light on the pins'
  side (``led_gain`` 0, ``gain`` 0.9, gradient 0.5).

Then what the camera or its driver does to a frame after the renderer
(the rest frame stays as rendered):

- ``jpeg60``: each frame through JPEG at quality 60 (a webcam's MJPEG
  stream);
- ``motion6``: a linear motion blur of 6 px at 30 degrees (a fast slide
  within one exposure);
- ``gamma0.6``: a tone curve ``255 (v / 255)^0.6`` (auto exposure, or a
  driver's gamma);
- ``shift1.5``: the whole frame moved by (1.5, -1.0) px (the camera's mount
  moved after calibration; no contact may come of it);
- ``hot_pixels``: 0.1 % of the pixels stuck at 255 and 0.1 % at 0;
- ``none``: ``NOMINAL`` as it is (contacts drawn as in every condition,
  from its own seeds: the row to compare the others with).

``--paired``: every condition draws frame ``i``'s contact and noise from
one generator, so that frame ``i`` holds the same contact in every
condition and the rows differ by the condition alone (without it each
condition draws its own contacts, and with a dozen contacts a row moves by
their sampling as much as by its condition). A second table then compares
dexitac's displacement field (``analyze --field-out``) with the renderer's
true pins, as ``match_quality.py`` does: of the pins a contact moved more
than 3 px, the share of rest markers found at their own pin, another pin,
no pin or lost; and, over every frame, how far the markers of the pins
that did not move (under 0.05 px: the contact-free frames' and those far
from a contact) appear to move (the false displacement a condition makes,
px; under ``shift1.5`` it is the shift itself).

Frames go to a temporary folder and are deleted (``--keep DIR``: to DIR, in
``render.py``'s layout, ``<condition>/{rest.png,frames/,truth.csv}``, with
dexitac's ``dexitac_default.csv``, kept). Writes
``<out>/<date>-render-stress.md``.
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import math
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
import match_quality as MQ  # noqa: E402
import render as R  # noqa: E402
import render_eval as E  # noqa: E402
from run import run_dexitac  # noqa: E402

CONDITIONS = {
    "blur3": dict(psf=3.0),
    "sharp": dict(psf=0.6),
    "dim_blur": dict(gain=1 / 3, vig=0.55, grad=0.30, e_per_dn=3.0, read=2.5, led_gain=0.5, psf=2.5),
    "bright": dict(gain=2.5),
    "bright_blur": dict(gain=2.0, psf=2.2),
    "noisy": dict(e_per_dn=2.0, read=6.0),
    "dark_corners": dict(vig=0.3),
    "leds_off": dict(led_gain=0.0, gain=0.9, grad=0.5),
    "jpeg60": dict(jpeg=60),
    "motion6": dict(motion_px=6.0, motion_deg=30.0),
    "gamma0.6": dict(gamma=0.6),
    "shift1.5": dict(shift_px=(1.5, -1.0)),
    "hot_pixels": dict(hot=0.001),
    "none": dict(),
}


def after_camera(img: np.ndarray, cond: dict, rng: np.random.Generator) -> np.ndarray:
    """What the camera's driver does to a rendered 8-bit frame (the keys of
    the conditions above that ``render.py`` does not know)."""
    if "motion_px" in cond:
        n = int(round(cond["motion_px"])) | 1
        k = np.zeros((n, n), np.float32)
        k[n // 2, :] = 1.0 / n
        rot = cv2.getRotationMatrix2D(((n - 1) / 2, (n - 1) / 2), cond["motion_deg"], 1.0)
        k = cv2.warpAffine(k, rot, (n, n))
        img = np.clip(np.round(cv2.filter2D(img.astype(np.float32), -1, k / k.sum())), 0, 255).astype(np.uint8)
    if "gamma" in cond:
        img = np.clip(np.round(255.0 * (img / 255.0) ** cond["gamma"]), 0, 255).astype(np.uint8)
    if "shift_px" in cond:
        dx, dy = cond["shift_px"]
        m = np.float32([[1, 0, dx], [0, 1, dy]])
        img = cv2.warpAffine(img, m, (img.shape[1], img.shape[0]), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    if "hot" in cond:
        u = rng.uniform(size=img.shape[:2])
        img = img.copy()
        img[u < cond["hot"]] = 255
        img[u > 1 - cond["hot"]] = 0
    if "jpeg" in cond:
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(cond["jpeg"])])
        assert ok
        img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    return img


def condition_contacts(name: str, sensor, seed: int, k: int, paired: bool = False):
    """Per frame of a condition: its index, its generator (the frame's noise
    comes next) and its contact (every odd frame, drawn as in ``nominal``);
    ``paired``: the same generators for every condition."""
    key = 4000 if paired else 3000 + list(CONDITIONS).index(name)
    for i in range(k):
        rng = np.random.default_rng([seed, key, i])
        yield i, rng, (R.sample_contact("nominal", sensor, rng) if i % 2 else None)


STILL_PX = 0.05  # a pin that moved less than this is still (``--paired``)


def pin_scores(field: Path, frames: list[tuple[str, np.ndarray]], pins_rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Over ``frames`` (name, true pins in that frame): the counts of
    ``match_quality.KINDS`` among the pins moved more than
    ``match_quality.MOVED_PX``, and the false displacements (px) of the rest
    markers whose pin moved less than ``STILL_PX``."""
    moved = np.zeros(len(MQ.KINDS), int)
    still: list[np.ndarray] = []
    for name, pins_now in frames:
        rest, now = MQ.read_field(field / f"{name}.csv")
        moved += MQ.score(rest, now, pins_rest, pins_now)["moved"]
        d0, pin = cKDTree(pins_rest).query(rest)
        true_move = pins_now[pin] - pins_rest[pin]
        sel = (d0 <= MQ.SAME_PIN_PX) & np.isfinite(now[:, 0]) & (np.hypot(*true_move.T) < STILL_PX)
        still.append(np.hypot(*(now[sel] - rest[sel] - true_move[sel]).T))
    return moved, np.concatenate(still) if still else np.zeros(0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dexitac", required=True)
    ap.add_argument("--frames-per-condition", type=int, default=12)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--conditions", nargs="*", default=list(CONDITIONS))
    ap.add_argument("--out", default="eval/results")
    ap.add_argument("--date", default=dt.date.today().isoformat())
    ap.add_argument("--keep", help="write the frames, truth and dexitac's CSVs to this folder (kept)")
    ap.add_argument("--paired", action="store_true", help="the same contacts in every condition, and the true pins' table")
    a = ap.parse_args()
    sensor = R.sensor_of("nominal", a.seed)
    scene = R.Scene(sensor)
    rest, _, _ = scene.render(None, dict(R.NOMINAL), np.random.default_rng([a.seed, 2000, len("dome")]))
    lines = [
        f"# dexitac on the renderer's dome under other conditions ({a.date})",
        "",
        f"`{' '.join(sys.argv)}`",
        "",
        f"Machine: {E.machine()}. Rest: the nominal rest frame; the rows are conditions.",
        "",
        *E.TABLE_HEAD,
    ]
    pin_lines: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(a.keep or tmp)
        for name in a.conditions:
            cond = dict(R.NOMINAL, **CONDITIONS[name])
            d = tmp / name
            (d / "frames").mkdir(parents=True, exist_ok=True)
            R.write_png(d / "rest.png", rest)
            truth = []
            pressed = []
            for i, rng, contact in condition_contacts(name, sensor, a.seed, a.frames_per_condition, a.paired):
                if a.paired:
                    pressed.append((f"{i:04d}", R.pins(sensor, contact)[0]))
                img, centre, n_vis = scene.render(contact, cond, rng)
                img = after_camera(img, cond, rng)
                if centre is not None and "shift_px" in cond:
                    centre = (centre[0] + cond["shift_px"][0], centre[1] + cond["shift_px"][1])
                R.write_png(d / "frames" / f"{i:04d}.png", img)
                cx, cy = centre if centre is not None else (math.nan, math.nan)
                truth.append({"frame": f"{i:04d}", "cx": cx, "cy": cy, "n_markers": n_vis})
            with open(d / "truth.csv", "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=list(truth[0]))
                w.writeheader()
                w.writerows(truth)
            field = d / "field"
            more = ("--field-out", str(field)) if a.paired else ()
            rows, _, note = run_dexitac(a.dexitac, d, d / "rest.png", d, "default", None, more=more)
            if note:
                print(f"{name}: {note}", file=sys.stderr)
                if a.paired:
                    return 1  # no field to score against the true pins
            pred = {r["frame"]: r for r in rows}
            lines.append(E.row(name, E.score([(t, pred.get(t["frame"])) for t in truth])))
            print(lines[-1], flush=True)
            if a.paired:
                moved, still = pin_scores(field, pressed, scene.rest_xy)
                shares = " | ".join(f"{100 * v / max(moved.sum(), 1):.1f} %" for v in moved)
                pin_lines.append(
                    f"| {name} | {moved.sum()} | {shares} | {np.median(still):.3f} / {np.percentile(still, 95):.3f} |"
                )
    if a.paired:
        lines += [
            "",
            "The same frames against the renderer's true pins (`--paired`):",
            "",
            "| condition | pins moved > 3 px | at their own pin | at another pin | at no pin | lost "
            f"| still pins (< {STILL_PX} px): false move median / p95 px |",
            "|---|---|---|---|---|---|---|",
            *pin_lines,
        ]
        print("\n".join(lines[-len(pin_lines) - 5 :]))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{a.date}-render-stress.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
