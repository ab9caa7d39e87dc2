#!/usr/bin/env python3
"""An independent renderer of synthetic TacTip-style frames with truth.

    python eval/render.py --out DIR [--seed N] [--frames-per-category K] [--no-parallax]

Writes, per category, ``DIR/<category>/rest.png``, ``DIR/<category>/frames/NNNN.png``
and ``DIR/<category>/truth.csv`` (``frame,cx,cy,n_markers,depth_mm``; ``cx, cy``
= the true contact centre in image px, NaN without contact; ``n_markers`` =
markers whose centre is inside the image), plus ``contacts.csv`` (the
indenter of each contact frame: kind, radii, depth, shear, distance of its
centre from the rim of the sensing area in px). 640x480, 8 bit; grey except
``two_colour`` (RGB). Seeded and deterministic (numpy, scipy, cv2 only).

Written from a physical description of the sensor, not from any other
generator. What it models:

- **Geometry.** ``dome``: the pin tips lie on a sphere of radius 17 mm
  (a cap up to 80 deg from the apex), seen from inside by a camera 5 mm
  behind the sphere's centre with a wide-angle lens (pinhole with
  Kannala-Brandt barrel distortion, rho = f alpha (1 - 0.15 alpha^2)):
  the 955 pins (rings of equal arc pitch) appear as ellipses foreshortened
  radially towards the rim, their radial pitch shrinking from ~14 to ~8 px.
  ``flat``: a flat rounded-rectangle skin 28 mm in front of a pinhole camera
  with slight barrel distortion, 1223 pins on a hexagonal lattice. Pin tips
  are flat discs with soft edges and a slight dome shading, projected
  through the local Jacobian of the camera (not Gaussians).
- **Skin.** A dark skin with low-contrast multi-scale noise and a woven
  fabric/grain pattern that moves with the skin; a bright housing ring with
  3 LEDs (saturated) and dust specks outside the dome; a grey frame with 2
  LEDs and dust around the flat skin.
- **Optics/sensor.** Illumination (vignetting, linear gradient), PSF = a
  Gaussian (sigma ~1 px at rest) plus a weak wide halo, Poisson shot noise
  and Gaussian read noise, clipping at 255 (bright pins saturate), 8-bit
  quantisation.
- **Contact** (see ``deflection`` and ``deform``): a rigid sphere (Hertz) or
  flat-ended cylinder (Boussinesq punch) pressed to depth delta. The skin's
  normal deflection w(r) is the elastic half-space solution, attenuated
  beyond the contact radius by exp(-(r - a)/4 mm) (finite gel layer) and
  smoothed over 0.6 mm (skin thickness). Each pin (lever L = 2 mm) tilts with
  the local slope, so its tip moves outwards by L sin(atan(-dw/dr)), plus a
  membrane stretch 0.15 delta min(r/a, a/r); the tip also moves towards the
  camera by w, the tilted tip disc is foreshortened by cos(tilt), and pins
  in the stretched patch grow by sqrt(1 + 0.3 div u) and dim by its square.
  Everything is multiplied by a rim factor that goes smoothly to 0 over
  3.5 mm at the clamped edge of the sensing area. Some frames add a
  tangential shear (the patch under the indenter travels with it).
  The truth centre is the indenter's centre on the skin (the pin-tip
  surface point on its axis, after any shear) projected as in the rest
  frame, i.e. in the rest frame's pixel coordinates; not the centroid of the
  displaced markers. (Pressed tips come nearer the camera, so the dimple
  itself also shifts in the image by parallax: up to ~1 px on the dome,
  camera 5 mm behind the sphere's centre, and up to ~4-10 px on the flat
  skin far from the optical axis, 28 mm away.) ``--no-parallax`` leaves
  that out: pressed pins are drawn at their rest depth, the rest unchanged.
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.interpolate import LinearNDInterpolator
from scipy.ndimage import gaussian_filter, gaussian_filter1d
from scipy.spatial import Delaunay

cv2.setNumThreads(1)

H, W = 480, 640
CATEGORIES = ["nominal", "flat_nominal", "harsh_light", "blur", "edge", "large", "two_colour", "no_contact"]

# contact model constants (mm)
L_PIN = 2.0  # pin lever: tip displacement = L sin(tilt)
GEL_DECAY = 4.0  # deflection decay beyond the contact radius
SKIN_SMOOTH = 0.6  # smoothing of the deflection profile (skin thickness)
STRETCH = 0.15  # membrane stretch coefficient (x delta)
RIM_CLAMP = 3.5  # width of the rim factor
SIZE_GAIN = 0.3  # marker growth with the divergence of the tip field


def smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


# ----------------------------------------------------------------------------
# sensors


class Dome:
    """Pin tips on a sphere cap, pinhole camera with barrel distortion inside."""

    kind = "dome"
    R = 17.0  # pin-tip sphere radius, mm
    TH_MAX = math.radians(80.0)
    D_CAM = 5.0  # camera behind the sphere's centre, mm
    K_DIST = -0.15  # wide-angle lens: rho = f alpha (1 + k alpha^2), alpha = ray angle
    N_PINS = 955
    RHO_RIM = 222.0  # image radius of the outermost ring, px
    CX, CY = 319.5, 241.5
    PIN_R = 0.42  # pin-tip radius, mm

    def __init__(self, rng: np.random.Generator, coloured: bool = False):
        self.f = 1.0
        self.f = self.RHO_RIM / self._rho_of_theta(np.array([self.TH_MAX]), self.R)[0]
        self.s_rim = self.R * self.TH_MAX
        self.q0 = self._layout(rng)
        self.n = len(self.q0)
        self.pitch = self._pitch
        th = np.linspace(0, self.TH_MAX, 2000)
        self._th_tab, self._rho_tab = th, self._rho_of_theta(th, self.R)
        self.bright = 245.0 * np.exp(rng.normal(0, 0.06, self.n))
        self.blue = np.zeros(self.n, bool)
        if coloured:
            self.blue[rng.permutation(self.n)[: self.n // 3]] = True
        self._static(rng)

    def _rho_of_theta(self, th: np.ndarray, r: float) -> np.ndarray:
        al = np.arctan2(r * np.sin(th), r * np.cos(th) + self.D_CAM)
        return self.f * al * (1 + self.K_DIST * al * al)

    def _layout(self, rng: np.random.Generator) -> np.ndarray:
        def rings(p: float) -> list[int]:
            k = np.arange(0, int(self.s_rim / p) + 1)
            th = k * p / self.R
            return [1] + [int(round(2 * math.pi * self.R * math.sin(t) / p)) for t in th[1:]]

        lo, hi = 0.5, 3.0
        for _ in range(60):
            mid = (lo + hi) / 2
            if sum(rings(mid)) > self.N_PINS:
                lo = mid
            else:
                hi = mid
        p = hi
        counts = rings(p)
        counts[-1] += self.N_PINS - sum(counts)  # hit the count exactly on the last ring
        self._pitch = p
        pts = []
        for k, c in enumerate(counts):
            s = k * p
            ph = rng.uniform(0, 2 * math.pi) + 2 * math.pi * np.arange(c) / c
            pts.append(np.stack([s * np.cos(ph), s * np.sin(ph)], 1))
        return np.concatenate(pts)[: self.N_PINS]

    # q: azimuthal-equidistant surface coords (mm); w: deflection towards the camera
    def to3d(self, q: np.ndarray, w: np.ndarray | float = 0.0) -> np.ndarray:
        s = np.hypot(q[..., 0], q[..., 1])
        th = s / self.R
        ph = np.arctan2(q[..., 1], q[..., 0])
        r = self.R - w
        return np.stack([r * np.sin(th) * np.cos(ph), r * np.sin(th) * np.sin(ph), r * np.cos(th)], -1)

    def project(self, p: np.ndarray) -> np.ndarray:
        vx, vy, vz = p[..., 0], p[..., 1], p[..., 2] + self.D_CAM
        h = np.hypot(vx, vy)
        al = np.arctan2(h, vz)
        rho = self.f * al * (1 + self.K_DIST * al * al)
        sc = np.where(h > 1e-9, rho / np.maximum(h, 1e-12), self.f / vz)
        return np.stack([self.CX + sc * vx, self.CY + sc * vy], -1)

    def tangent_basis(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Orthonormal tangent vectors (e_radial, e_azimuthal) at q, and the
        q-plane tangential scale factor sin(theta)/theta."""
        s = np.hypot(q[..., 0], q[..., 1])
        th = s / self.R
        ph = np.arctan2(q[..., 1], q[..., 0])
        e1 = np.stack([np.cos(th) * np.cos(ph), np.cos(th) * np.sin(ph), -np.sin(th)], -1)
        e2 = np.stack([-np.sin(ph), np.cos(ph), np.zeros_like(ph)], -1)
        fac = np.where(th > 1e-6, np.sin(th) / np.maximum(th, 1e-9), 1.0)
        return e1, e2, ph, fac

    def rim_factor(self, q: np.ndarray) -> np.ndarray:
        return smoothstep((self.s_rim - np.hypot(q[..., 0], q[..., 1])) / RIM_CLAMP)

    def rim_distance_px(self, q: np.ndarray) -> np.ndarray:
        rho = np.interp(np.hypot(q[..., 0], q[..., 1]) / self.R, self._th_tab, self._rho_tab)
        return self.RHO_RIM - rho

    def q_at_rho(self, rho: float, ang: float) -> np.ndarray:
        th = np.interp(rho, self._rho_tab, self._th_tab)
        s = th * self.R
        return np.array([s * math.cos(ang), s * math.sin(ang)])

    def sample_contact(self, rng: np.random.Generator, min_rim_px: float) -> np.ndarray:
        while True:
            r = self.s_rim * math.sqrt(rng.uniform())
            a = rng.uniform(0, 2 * math.pi)
            q = np.array([r * math.cos(a), r * math.sin(a)])
            if self.rim_distance_px(q) >= min_rim_px:
                return q

    def _static(self, rng: np.random.Generator) -> None:
        y, x = np.mgrid[0:H, 0:W].astype(np.float64)
        rr = np.hypot(x - self.CX, y - self.CY)
        ang = np.arctan2(y - self.CY, x - self.CX)
        r0 = self.RHO_RIM
        # dark skin up to a little beyond the outermost ring, then a dark gap
        self.skin_mask = smoothstep((r0 + 7 - rr) / 2.5 + 0.5)
        self.skin_level = 20.0 + 14.0 * np.exp(-np.clip(r0 + 7 - rr, 0, None) / 10.0)  # rim glow
        ring = np.exp(-0.5 * ((rr - (r0 + 30)) / 9.0) ** 2)
        housing = 14.0 + 55.0 * smoothstep((rr - r0 - 14) / 6) + 150.0 * ring
        housing *= 1 + 0.08 * np.cos(3 * ang + 0.7)
        housing += 3.0 * gaussian_filter(rng.normal(0, 1, (H, W)), 3) * 3
        self.housing = housing
        # LEDs on the ring
        led = np.zeros((H, W))
        for a in rng.uniform(0, 2 * math.pi) + np.array([0.0, 2.1, 4.2]) + rng.normal(0, 0.15, 3):
            lx, ly = self.CX + (r0 + 29) * math.cos(a), self.CY + (r0 + 29) * math.sin(a)
            d = np.hypot(x - lx, y - ly)
            led += 1400.0 * smoothstep((7.5 - d) / 2.0) + 250.0 * np.exp(-0.5 * (d / 9.0) ** 2)
        self.led = led
        self.dust = _dust(rng, lambda px, py: np.hypot(px - self.CX, py - self.CY) > r0 + 14, 14)
        self.texture = _skin_texture(rng)


class Flat:
    """Flat rounded-rectangle skin in front of a pinhole camera."""

    kind = "flat"
    D_CAM = 28.0  # mm
    SCALE = 10.0  # px per mm at the optical centre
    K_DIST = 0.04
    HALF = (30.2, 22.2)  # rounded rectangle half sizes, mm
    CORNER = 4.0
    N_PINS = 1223
    CX, CY = 319.5, 239.5
    PIN_R = 0.5

    def __init__(self, rng: np.random.Generator):
        self.f = self.SCALE * self.D_CAM
        self.q0 = self._layout(rng)
        self.n = len(self.q0)
        self.bright = 235.0 * np.exp(rng.normal(0, 0.06, self.n))
        self.blue = np.zeros(self.n, bool)
        self._static(rng)

    def sdf(self, q: np.ndarray) -> np.ndarray:
        hx, hy = self.HALF[0] - self.CORNER, self.HALF[1] - self.CORNER
        dx, dy = np.abs(q[..., 0]) - hx, np.abs(q[..., 1]) - hy
        out = np.hypot(np.clip(dx, 0, None), np.clip(dy, 0, None))
        return out + np.minimum(np.maximum(dx, dy), 0) - self.CORNER

    def _layout(self, rng: np.random.Generator) -> np.ndarray:
        def lattice(p: float, ox: float, oy: float, m: float) -> np.ndarray:
            ny = int(self.HALF[1] / (p * 0.866)) + 2
            nx = int(self.HALF[0] / p) + 2
            j, i = np.mgrid[-ny : ny + 1, -nx : nx + 1]
            q = np.stack([(i + 0.5 * (j % 2) + ox) * p, (j + oy) * p * math.sqrt(3) / 2], -1).reshape(-1, 2)
            return q[self.sdf(q) <= -m * p]

        best = None  # off-centre lattice phases break the 180-degree symmetry (odd counts)
        for p in np.linspace(1.50, 1.60, 101):
            for ox in np.arange(0.0, 1.0, 0.1):
                for oy in np.arange(0.0, 1.0, 1 / 6):
                    q = lattice(p, ox, oy, 0.55)
                    if best is None or abs(len(q) - self.N_PINS) < abs(len(best[1]) - self.N_PINS):
                        best = (p, q)
                    if len(best[1]) == self.N_PINS:
                        break
                if len(best[1]) == self.N_PINS:
                    break
            if len(best[1]) == self.N_PINS:
                break
        self.pitch = best[0]
        q = best[1]
        if len(q) > self.N_PINS:  # drop the few pins nearest the edge
            q = q[np.argsort(self.sdf(q), kind="stable")[: self.N_PINS]]
        return q + rng.normal(0, 0.02, q.shape)  # moulding tolerance

    def to3d(self, q: np.ndarray, w: np.ndarray | float = 0.0) -> np.ndarray:
        return np.stack([q[..., 0], q[..., 1], self.D_CAM - w + 0 * q[..., 0]], -1)

    def project(self, p: np.ndarray) -> np.ndarray:
        tx, ty = p[..., 0] / p[..., 2], p[..., 1] / p[..., 2]
        d = 1 + self.K_DIST * (tx * tx + ty * ty)
        return np.stack([self.CX + self.f * tx / d, self.CY + self.f * ty / d], -1)

    def tangent_basis(self, q: np.ndarray):
        one, zero = np.ones(q.shape[:-1]), np.zeros(q.shape[:-1])
        e1 = np.stack([one, zero, zero], -1)
        e2 = np.stack([zero, one, zero], -1)
        return e1, e2, zero, one

    def rim_factor(self, q: np.ndarray) -> np.ndarray:
        return smoothstep(-self.sdf(q) / RIM_CLAMP)

    def rim_distance_px(self, q: np.ndarray) -> np.ndarray:
        return -self.sdf(q) * self.SCALE

    def sample_contact(self, rng: np.random.Generator, min_rim_px: float) -> np.ndarray:
        while True:
            q = rng.uniform(-1, 1, 2) * np.array(self.HALF)
            if self.rim_distance_px(q) >= min_rim_px:
                return q

    def _static(self, rng: np.random.Generator) -> None:
        y, x = np.mgrid[0:H, 0:W].astype(np.float64)
        # sdf in image space: map pixels back to the skin plane (the frame is static)
        tx, ty = (x - self.CX) / self.f, (y - self.CY) / self.f
        r2 = tx * tx + ty * ty
        # invert the division model approximately (one fixed-point step suffices here)
        for _ in range(3):
            d = 1 + self.K_DIST * r2
            ux, uy = (x - self.CX) / self.f * d, (y - self.CY) / self.f * d
            r2 = ux * ux + uy * uy
        sd = self.sdf(np.stack([ux * self.D_CAM, uy * self.D_CAM], -1)) * self.SCALE
        self.skin_mask = smoothstep((2.0 - sd) / 3.0)
        self.skin_level = 22.0 + 10.0 * np.exp(-np.clip(-sd, 0, None) / 8.0)
        housing = 75.0 + 20.0 * smoothstep((sd - 4) / 10) + 6 * gaussian_filter(rng.normal(0, 1, (H, W)), 4) * 3
        self.housing = housing
        led = np.zeros((H, W))
        for lx, ly in [(6.0, 120.0 + rng.uniform(-20, 20)), (633.0, 360.0 + rng.uniform(-20, 20))]:
            d = np.hypot(x - lx, y - ly)
            led += 1400.0 * smoothstep((6.5 - d) / 2.0) + 200.0 * np.exp(-0.5 * (d / 8.0) ** 2)
        self.led = led
        self.dust = _dust(rng, lambda px, py: self._outside(px, py), 10)
        self.texture = _skin_texture(rng)

    def _outside(self, px: float, py: float) -> bool:
        i, j = int(round(py)), int(round(px))
        return 0 <= i < H and 0 <= j < W and self.skin_mask[i, j] < 0.01


def _skin_texture(rng: np.random.Generator) -> np.ndarray:
    """Low-contrast multi-scale noise plus a woven fabric and a fine grain (DN)."""
    t = np.zeros((H, W))
    for sig, amp in [(1.5, 1.0), (5.0, 1.6), (18.0, 2.2), (50.0, 2.5)]:
        n = gaussian_filter(rng.normal(0, 1, (H, W)), sig)
        t += amp * n / n.std()
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    a = rng.uniform(0, math.pi)
    u, v = x * math.cos(a) + y * math.sin(a), -x * math.sin(a) + y * math.cos(a)
    per = rng.uniform(3.0, 3.6)
    weave = np.sin(2 * math.pi * u / per) * np.sin(2 * math.pi * v / per)
    weave = np.where(np.sin(math.pi * u / per) * np.sin(math.pi * v / per) > 0, weave, 0.6 * weave)
    grain = gaussian_filter(rng.normal(0, 1, (H, W)), 0.6)
    return t + 1.2 * weave + 0.9 * grain / grain.std()


def _dust(rng: np.random.Generator, where, n: int) -> np.ndarray:
    out = []
    while len(out) < n:
        px, py = rng.uniform(0, W), rng.uniform(0, H)
        if where(px, py):
            out.append((px, py, rng.uniform(0.7, 2.0), rng.uniform(60, 180)))
    return np.array(out)


# ----------------------------------------------------------------------------
# contact model


def deflection(kind: str, delta: float, a: float, ri: float):
    """Radial profile w(r) of the skin's normal deflection (mm) and its slope."""
    r = np.linspace(0, 40.0, 4001)
    dr = r[1] - r[0]
    rho = np.maximum(r / a, 1e-9)
    out = rho > 1
    w = np.empty_like(r)
    if kind == "sphere":  # Hertz: inside the indenter's shape, outside the half-space solution
        w[~out] = delta - r[~out] ** 2 / (2 * ri)
        ro = rho[out]
        w[out] = delta / math.pi * ((2 - ro**2) * np.arcsin(1 / ro) + np.sqrt(ro**2 - 1))
    else:  # flat punch (Boussinesq)
        w[~out] = delta
        w[out] = 2 * delta / math.pi * np.arcsin(1 / rho[out])
    w *= np.exp(-np.clip(r - a, 0, None) / GEL_DECAY)
    w = gaussian_filter1d(w, SKIN_SMOOTH / dr, mode="mirror")
    slope = np.gradient(w, dr)
    return r, w, slope


# ``--no-parallax``: pressed pins are drawn at their rest depth (their place
# on the skin, tilt and size as pressed), as a renderer without the dimple's
# depth would show them.
PARALLAX = True


def deform(sensor, contact: dict | None):
    """Deformed pin tips: 3-D positions, tilt, size and brightness factors, and
    the truth centre (image px)."""
    q0 = sensor.q0
    n = len(q0)
    if contact is None:
        return sensor.to3d(q0), q0, np.zeros(n), np.zeros((n, 2)), np.ones(n), None
    g0 = sensor.rim_factor(q0)
    c0, shear, a = contact["c"], contact["shear"], contact["a"]
    # tangential shear: the patch under the indenter travels with it
    sh = np.exp(-0.5 * (np.sum((q0 - c0) ** 2, 1) / (1.3 * a) ** 2))
    q1 = q0 + (g0 * sh)[:, None] * shear[None, :]
    c = c0 + sensor.rim_factor(c0) * shear
    r_tab, w_tab, s_tab = deflection(contact["kind"], contact["delta"], a, contact["ri"])
    d = q1 - c
    r = np.hypot(d[:, 0], d[:, 1])
    u_dir = d / np.maximum(r, 1e-9)[:, None]
    w = np.interp(r, r_tab, w_tab)
    slope = np.interp(r, r_tab, s_tab)
    tilt = np.arctan(-slope)  # > 0: tip leans away from the contact
    mem = STRETCH * contact["delta"] * np.minimum(r / a, a / np.maximum(r, 1e-9))

    def ur_of(rr):
        sl = np.interp(rr, r_tab, s_tab)
        return L_PIN * np.sin(np.arctan(-sl)) + STRETCH * contact["delta"] * np.minimum(rr / a, a / np.maximum(rr, 1e-9))

    ur = L_PIN * np.sin(tilt) + mem
    # divergence of the radial tip field (areal stretch), for size and brightness
    h = 0.05
    dur = (ur_of(r + h) - ur_of(np.maximum(r - h, 0))) / (r + h - np.maximum(r - h, 0))
    div = dur + ur / np.maximum(r, 0.3)
    q2 = q1 + (g0 * ur)[:, None] * u_dir
    weff = g0 * w if PARALLAX else 0.0
    p3 = sensor.to3d(q2, weff)
    tilt = g0 * tilt
    grow = np.sqrt(np.clip(1 + SIZE_GAIN * g0 * div, 0.6, 1.6))
    # truth: the skin point on the indenter's axis, where the rest frame shows it
    truth = sensor.project(sensor.to3d(c[None, :], 0.0))[0]
    return p3, q2, tilt, u_dir, grow, truth


def marker_jacobians(sensor, p3, q2, tilt, u_dir, grow):
    """2x2 image Jacobian of each pin-tip disc (columns: its two semi-axes, px)."""
    e1, e2, ph, fac = sensor.tangent_basis(q2)
    # direction away from the contact in the orthonormal tangent basis
    cr = u_dir[:, 0] * np.cos(ph) + u_dir[:, 1] * np.sin(ph)
    ct = -u_dir[:, 0] * np.sin(ph) + u_dir[:, 1] * np.cos(ph)
    tx, ty = cr, ct * fac
    nn = np.maximum(np.hypot(tx, ty), 1e-9)
    tx, ty = tx / nn, ty / nn
    k = 1 - np.cos(tilt)
    # A = r grow (I - k t t^T), in the (e1, e2) basis
    rr = sensor.PIN_R * grow
    a11, a12, a22 = rr * (1 - k * tx * tx), -rr * k * tx * ty, rr * (1 - k * ty * ty)
    v1 = e1 * a11[:, None] + e2 * a12[:, None]
    v2 = e1 * a12[:, None] + e2 * a22[:, None]
    eps = 1e-3
    p0 = sensor.project(p3)
    j1 = (sensor.project(p3 + eps * v1) - p0) / eps
    j2 = (sensor.project(p3 + eps * v2) - p0) / eps
    return p0, np.stack([j1, j2], -1)  # (n, 2, 2): columns are the semi-axes


def pins(sensor, contact):
    """The pins pressed by ``contact`` (None: at rest): image positions, the
    Jacobians of their discs, their tilt and growth, and the truth centre."""
    p3, q2, tilt, u_dir, grow, truth = deform(sensor, contact)
    xy, jac = marker_jacobians(sensor, p3, q2, tilt, u_dir, grow)
    return xy, jac, tilt, grow, truth


def in_frame(xy: np.ndarray) -> np.ndarray:
    """Which of the pin centres ``xy`` lie inside the image (the ones truth counts)."""
    return (xy[:, 0] >= -0.5) & (xy[:, 0] < W - 0.5) & (xy[:, 1] >= -0.5) & (xy[:, 1] < H - 0.5)


def splat(xy: np.ndarray, jac: np.ndarray, amp: np.ndarray, edge_px: float = 0.9, shade: bool = True) -> np.ndarray:
    """Soft-edged elliptical discs (flat top, slight dome) summed into an image."""
    out = np.zeros(H * W)
    if len(xy) == 0:
        return out.reshape(H, W)
    sv = np.linalg.svd(jac, compute_uv=False)
    k = int(min(16, math.ceil(sv.max() + 2.5)))
    oy, ox = np.mgrid[-k : k + 1, -k : k + 1]
    ox, oy = ox.ravel(), oy.ravel()
    ix, iy = np.round(xy[:, 0]).astype(int), np.round(xy[:, 1]).astype(int)
    px, py = ix[:, None] + ox[None, :], iy[:, None] + oy[None, :]
    dx, dy = px - xy[:, 0:1], py - xy[:, 1:2]
    inv = np.linalg.inv(jac)
    vx = inv[:, 0, 0:1] * dx + inv[:, 0, 1:2] * dy
    vy = inv[:, 1, 0:1] * dx + inv[:, 1, 1:2] * dy
    s = np.hypot(vx, vy)
    dist = np.hypot(dx, dy)
    edge = (s - 1) * dist / np.maximum(s, 1e-9)  # px from the ellipse's edge along the ray
    cov = smoothstep(0.5 - edge / edge_px)
    if shade:
        cov = cov * (0.8 + 0.2 * np.sqrt(np.clip(1 - s * s, 0, 1)))
    val = amp[:, None] * cov
    ok = (px >= 0) & (px < W) & (py >= 0) & (py < H) & (val > 0)
    out += np.bincount((py * W + px)[ok], weights=val[ok], minlength=H * W)
    return out.reshape(H, W)


# ----------------------------------------------------------------------------
# frames


def light_field(gain: float, vig_corner: float, grad: float, grad_dir: float) -> np.ndarray:
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    r = np.hypot(x - W / 2, y - H / 2) / math.hypot(W / 2, H / 2)
    v = 1 - (1 - vig_corner) * r**2
    u = ((x - W / 2) * math.cos(grad_dir) + (y - H / 2) * math.sin(grad_dir)) / math.hypot(W / 2, H / 2) / 2
    return gain * v * (1 + grad * u)


def psf(img: np.ndarray, sigma: float) -> np.ndarray:
    core = cv2.GaussianBlur(img, (0, 0), sigma)
    halo = cv2.GaussianBlur(img, (0, 0), 4 * sigma + 2)
    return 0.92 * core + 0.08 * halo


class Scene:
    """Per-sensor static parts and the rest marker positions (for warping the skin)."""

    def __init__(self, sensor):
        self.s = sensor
        p3, q2, tilt, ud, grow, _ = deform(sensor, None)
        self.rest_xy, self.rest_jac = marker_jacobians(sensor, p3, q2, tilt, np.tile([1.0, 0.0], (sensor.n, 1)), grow)
        self.tri = Delaunay(self.rest_xy)
        gy, gx = np.mgrid[0 : H + 8 : 8, 0 : W + 8 : 8].astype(np.float64)
        self.grid = np.stack([gx.ravel(), gy.ravel()], 1)
        self.gshape = gx.shape
        yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
        self.xx, self.yy = xx, yy
        d = sensor.dust
        jd = np.zeros((len(d), 2, 2))
        jd[:, 0, 0] = jd[:, 1, 1] = d[:, 2]
        self.dust_img = splat(d[:, :2], jd, d[:, 3], edge_px=0.8, shade=False)

    def render(self, contact, cond: dict, rng: np.random.Generator):
        s = self.s
        xy, jac, tilt, grow, truth = pins(s, contact)
        tex = s.texture
        if contact is not None:  # the skin's texture moves with the skin
            disp = xy - self.rest_xy
            f = LinearNDInterpolator(self.tri, disp, fill_value=0.0)(self.grid)
            fx = cv2.resize(f[:, 0].reshape(self.gshape).astype(np.float32), (self.gshape[1] * 8, self.gshape[0] * 8), interpolation=cv2.INTER_LINEAR)[:H, :W]
            fy = cv2.resize(f[:, 1].reshape(self.gshape).astype(np.float32), (self.gshape[1] * 8, self.gshape[0] * 8), interpolation=cv2.INTER_LINEAR)[:H, :W]
            tex = cv2.remap(tex.astype(np.float32), self.xx - fx, self.yy - fy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT).astype(np.float64)
        # pins: brightness falls with tilt (cos) and stretch (area)
        amp = s.bright * (0.55 + 0.45 * np.cos(tilt)) / grow**2
        amp = amp * cond.get("pin_gain", 1.0)
        skin = s.skin_mask * (s.skin_level + tex)
        base = skin + (1 - s.skin_mask) * s.housing + self.dust_img
        lf = light_field(cond["gain"], cond["vig"], cond["grad"], cond["grad_dir"])
        inside = in_frame(xy)
        if s.blue.any():
            white = splat(xy[~s.blue], jac[~s.blue], amp[~s.blue] - 20)
            blue = splat(xy[s.blue], jac[s.blue], amp[s.blue] - 20)
            tint = np.array([1.0, 0.88, 0.78])  # warm skin, BGR order below reversed
            bcol = np.array([0.28, 0.50, 1.0])  # R, G, B of the blue pins
            chans = []
            for ch in range(3):
                rad = (base * tint[ch] + white + blue * bcol[ch]) * lf + s.led * cond["led_gain"]
                chans.append(rad)
            img = np.stack(chans, -1)
        else:
            img = (base + splat(xy, jac, amp - 20)) * lf + s.led * cond["led_gain"]
        img = _camera(img, cond, rng)
        n_vis = int(inside.sum())
        return img, truth, n_vis


def _camera(rad: np.ndarray, cond: dict, rng: np.random.Generator) -> np.ndarray:
    rad = np.maximum(rad, 0)
    if rad.ndim == 3:
        rad = np.stack([psf(rad[..., c], cond["psf"]) for c in range(3)], -1)
    else:
        rad = psf(rad, cond["psf"])
    k = cond["e_per_dn"]
    img = rng.poisson(np.maximum(rad, 0) * k) / k + rng.normal(0, cond["read"], rad.shape) + 1.5
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


NOMINAL = dict(gain=1.0, vig=0.85, grad=0.04, grad_dir=0.3, psf=1.0, e_per_dn=10.0, read=1.2, led_gain=1.0)


def frame_condition(cat: str, rng: np.random.Generator) -> dict:
    c = dict(NOMINAL)
    c["gain"] = rng.uniform(0.97, 1.03)
    c["grad_dir"] = 0.3 + rng.normal(0, 0.1)
    c["psf"] = rng.uniform(0.9, 1.1)
    if cat == "harsh_light":
        c.update(gain=1 / 3, vig=rng.uniform(0.45, 0.65), grad=0.30, grad_dir=rng.uniform(0, 2 * math.pi),
                 e_per_dn=3.0, read=2.5, led_gain=0.5)
    elif cat == "blur":
        c["psf"] = rng.uniform(1.8, 2.8)
    elif cat == "no_contact":
        c.update(gain=rng.uniform(0.85, 1.1), vig=rng.uniform(0.72, 0.9), grad=rng.uniform(0, 0.12),
                 grad_dir=rng.uniform(0, 2 * math.pi), psf=rng.uniform(0.9, 1.4), read=rng.uniform(1.0, 2.5))
    return c


def sample_contact(cat: str, sensor, rng: np.random.Generator) -> dict:
    pitch = sensor.pitch
    if cat == "large":
        a = rng.uniform(3, 5) * pitch
        delta = rng.uniform(0.35, 0.6) * a  # edge slope delta/a: a visible press, 1.3-4.7 mm
        kind = "sphere" if rng.uniform() < 0.6 else "punch"
        if kind == "punch":
            delta *= 0.5
        ri = a * a / delta if kind == "sphere" else a
        scale = 10.5  # rough px per mm
        c = sensor.sample_contact(rng, 40 + a * scale)
    else:
        if rng.uniform() < 0.7:
            kind, ri, delta = "sphere", rng.uniform(4, 10), rng.uniform(0.7, 2.2)
            a = math.sqrt(ri * delta)
        else:
            kind, a, delta = "punch", rng.uniform(1.5, 3.5), rng.uniform(0.5, 1.5)
            ri = a
        if cat == "edge":
            delta = max(delta, 1.0)
            if isinstance(sensor, Dome):
                c = sensor.q_at_rho(sensor.RHO_RIM - rng.uniform(25, 70), rng.uniform(0, 2 * math.pi))
            else:
                raise ValueError("edge is a dome category")
        else:
            c = sensor.sample_contact(rng, 70)
    shear = np.zeros(2)
    if rng.uniform() < 0.3:
        ang = rng.uniform(0, 2 * math.pi)
        shear = rng.uniform(0.1, 0.35) * np.array([math.cos(ang), math.sin(ang)])
    return dict(kind=kind, a=a, ri=ri, delta=delta, c=c, shear=shear)


def sensor_of(cat: str, seed: int):
    """The sensor a category's frames show (its pins laid out by ``seed``)."""
    if cat == "flat_nominal":
        return Flat(np.random.default_rng([seed, 1001]))
    return Dome(np.random.default_rng([seed, 1000]), coloured=cat == "two_colour")


def frame_contacts(cat: str, sensor, seed: int, k: int):
    """Per frame of a category: its index, its generator (after the contact
    was drawn; the frame's conditions and noise come next) and its contact
    (None for a frame without one, 10 % of them, or all in no_contact)."""
    rng = np.random.default_rng([seed, CATEGORIES.index(cat)])
    n_free = k if cat == "no_contact" else max(1, round(0.1 * k))
    free = set(rng.choice(k, n_free, replace=False).tolist())
    for i in range(k):
        frng = np.random.default_rng([seed, CATEGORIES.index(cat), i])
        yield i, frng, (None if i in free else sample_contact(cat, sensor, frng))


def write_png(path: Path, img: np.ndarray) -> None:
    cv2.imwrite(str(path), img[..., ::-1] if img.ndim == 3 else img)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--frames-per-category", type=int, default=24)
    ap.add_argument("--categories", nargs="*", default=CATEGORIES)
    ap.add_argument("--no-parallax", action="store_true", help="pressed pins drawn at their rest depth (no parallax)")
    a = ap.parse_args()
    global PARALLAX
    PARALLAX = not a.no_parallax
    out = Path(a.out)
    t0 = time.time()
    sensors = {
        "dome": Scene(sensor_of("nominal", a.seed)),
        "flat": Scene(sensor_of("flat_nominal", a.seed)),
        "dome_rgb": Scene(sensor_of("two_colour", a.seed)),
    }
    rests = {}
    for name, sc in sensors.items():
        rests[name], _, _ = sc.render(None, dict(NOMINAL), np.random.default_rng([a.seed, 2000, len(name)]))
    for ci, cat in enumerate(a.categories):
        sname = {"flat_nominal": "flat", "two_colour": "dome_rgb"}.get(cat, "dome")
        sc = sensors[sname]
        d = out / cat
        (d / "frames").mkdir(parents=True, exist_ok=True)
        for old in (d / "frames").glob("*.png"):
            old.unlink()
        write_png(d / "rest.png", rests[sname])
        k = a.frames_per_category
        rows, crow = [], []
        for i, frng, contact in frame_contacts(cat, sc.s, a.seed, k):
            cond = frame_condition(cat, frng)
            img, truth, n_vis = sc.render(contact, cond, frng)
            name = f"{i:04d}"
            write_png(d / "frames" / f"{name}.png", img)
            cx, cy = (truth if truth is not None else (math.nan, math.nan))
            rows.append([name, f"{cx:.3f}", f"{cy:.3f}", n_vis, f"{contact['delta']:.3f}" if contact else "0"])
            if contact:
                rd = sc.s.rim_distance_px(contact["c"])
                crow.append([name, contact["kind"], f"{contact['a']:.3f}", f"{contact['ri']:.3f}", f"{contact['delta']:.3f}",
                             f"{contact['shear'][0]:.3f}", f"{contact['shear'][1]:.3f}", f"{rd:.1f}"])
        with open(d / "truth.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["frame", "cx", "cy", "n_markers", "depth_mm"])
            w.writerows(rows)
        with open(d / "contacts.csv", "w", newline="") as f:  # the indenter of each contact frame
            w = csv.writer(f)
            w.writerow(["frame", "kind", "contact_radius_mm", "indenter_radius_mm", "depth_mm", "shear_x_mm", "shear_y_mm", "rim_distance_px"])
            w.writerows(crow)
        print(f"{cat}: {k} frames ({sname}, {sc.s.n} pins, pitch {sc.s.pitch:.3f} mm) -> {d}")
    print(f"rendered in {time.time() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
