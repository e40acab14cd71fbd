"""Tree trunks and poles from one laser scan: small arcs, their centres and diameters.

A trunk of diameter ``d`` whose centre is at distance ``D`` from the laser is seen as a run
of neighbouring beams whose ranges stand clearly in front of the beams on both sides (an
occlusion edge on each side) and span the angle ``Δφ = 2 asin(R / D)``, ``R = d / 2``. The
nearest surface point is at ``r = D - R``, so ``sin(Δφ / 2) = R / (r + R)`` and

    R = r s / (1 - s),    s = sin(Δφ / 2)                                         (1)

which is the chord formula ``d ≈ 2 r sin(Δφ / 2)`` corrected for the visible arc (the
tangent points lie behind the nearest point). :func:`extract_trees` takes the scan apart at
range jumps and keeps a run of beams as a trunk when

* both of its neighbours are farther by more than the jump (or no return): an occluded
  trunk — a nearer object beside it — shows only part of its width and is refused, as is a
  run touching either end of the scan;
* its number of beams is what a trunk of diameter ``min_diameter`` to ``max_diameter`` at
  that range gives: with ``n`` beams at increment ``δ`` the trunk spans between
  ``(n - 1) δ`` and ``(n + 1) δ``, so ``n`` must lie within one beam of
  ``Δφ(d, r) / δ`` for some ``d`` in the bounds. Near the laser even a thin trunk covers
  many beams; far away one or two suffice, and a wall seen over a few beams is refused by
  its depth (the next check);
* its depth (the spread of its ranges) is at most the radius plus the range noise, and it
  is convex toward the laser: no inner beam is farther than the chord between its two end
  points by more than the noise (a trunk bulges toward the sensor, a corner away from it).

The diameter follows from (1) with ``Δφ = n δ`` (the expected span of ``n`` beams) and ``r``
the smallest range. The centre lies at ``r + R`` along the middle bearing of the run. With at
least ``fit_beams`` beams the circle is also fitted to the points by linear least squares
(Kåsa: ``x² + y² + a x + b y + c = 0``), and the fit replaces (1) when its radius lies in the
bounds and its centre is behind the points; the result records which was used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray
from slamkit.errors import ConfigError, InputError, ShapeError

__all__ = ["TreeDetections", "TreeExtractorConfig", "extract_trees"]


@dataclass(frozen=True)
class TreeExtractorConfig:
    """Settings of :func:`extract_trees` (metres)."""

    max_range: float = 40.0
    """Only beams shorter than this are looked at [m]: beyond ~40 m a trunk is one or two
    beams and its width says nothing (the published Victoria Park detections reach 38 m)."""
    jump: float = 1.0
    """A range step larger than this between neighbouring beams separates two objects, and
    both neighbours of a trunk must be this much farther than its nearest point [m]."""
    min_diameter: float = 0.1
    """The smallest trunk [m]."""
    max_diameter: float = 1.0
    """The largest trunk [m]."""
    range_sigma: float = 0.05
    """The laser's range noise [m]: the tolerance of the depth and convexity checks."""
    fit_beams: int = 6
    """From this many beams on, the circle is fitted to the points (Kåsa)."""

    def __post_init__(self) -> None:
        for name in ("max_range", "jump", "min_diameter", "range_sigma"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a number > 0, got {getattr(self, name)}")
        if not self.max_diameter > self.min_diameter:
            raise ConfigError(
                f"max_diameter: expected more than min_diameter = {self.min_diameter}, "
                f"got {self.max_diameter}"
            )
        if self.fit_beams < 3:
            raise ConfigError(f"fit_beams: expected at least 3, got {self.fit_beams}")


@dataclass(frozen=True)
class TreeDetections:
    """The trunks of one scan in the laser frame: ``ranges (K,)`` and ``bearings (K,)`` of
    the centres [m, rad, the scan's angles], ``diameters (K,)`` [m] (the signature),
    ``beams (K,)`` the number of beams on each trunk, ``fitted (K,)`` whether the circle fit
    (not the angular width) gave the centre and diameter."""

    ranges: FloatArray
    bearings: FloatArray
    diameters: FloatArray
    beams: NDArray[np.int64]
    fitted: NDArray[np.bool_]

    def __len__(self) -> int:
        return int(self.ranges.size)

    def points(self) -> FloatArray:
        """The centres ``(K, 2)`` in the laser frame."""
        return np.column_stack(
            [self.ranges * np.cos(self.bearings), self.ranges * np.sin(self.bearings)]
        )


def _radius_from_width(r_near: FloatArray, width: FloatArray) -> FloatArray:
    # (1): R = r s / (1 - s), s = sin(Δφ / 2); s < 1 for any width below π.
    s = np.sin(np.minimum(width, np.pi * 0.99) / 2.0)
    return np.asarray(r_near * s / (1.0 - s), dtype=np.float64)


def _kasa_fit(x: FloatArray, y: FloatArray) -> tuple[float, float, float] | None:
    """Centre and radius of the circle ``x² + y² + a x + b y + c = 0`` closest (algebraic
    least squares) to the points, or None when the points are degenerate."""
    a_mat = np.column_stack([x, y, np.ones_like(x)])
    rhs = -(x * x + y * y)
    sol, _, rank, _ = np.linalg.lstsq(a_mat, rhs, rcond=None)
    if rank < 3:
        return None
    cx, cy = -sol[0] / 2.0, -sol[1] / 2.0
    r2 = cx * cx + cy * cy - sol[2]
    if not r2 > 0:
        return None
    return float(cx), float(cy), float(np.sqrt(r2))


def _runs(valid: NDArray[np.bool_], ranges: FloatArray, jump: float) -> list[tuple[int, int]]:
    """``[a, b)`` runs of valid beams without a range step above ``jump`` inside."""
    step = np.abs(np.diff(ranges)) > jump
    brk = ~valid[:-1] | ~valid[1:] | step
    starts = np.r_[0, np.flatnonzero(brk) + 1]
    ends = np.r_[np.flatnonzero(brk) + 1, valid.size]
    return [(int(a), int(b)) for a, b in zip(starts, ends, strict=True) if valid[a]]


def extract_trees(
    ranges: ArrayLike,
    angles: ArrayLike,
    config: TreeExtractorConfig | None = None,
) -> TreeDetections:
    """The trunks in one scan: ``ranges (B,)`` [m] at evenly spaced, increasing ``angles
    (B,)`` [rad]; a range at or beyond ``config.max_range`` (or not finite) is no return.
    See the module docstring for the checks and the estimates."""
    cfg = config or TreeExtractorConfig()
    r = np.asarray(ranges, dtype=np.float64).reshape(-1)
    phi = np.asarray(angles, dtype=np.float64).reshape(-1)
    if r.size != phi.size or r.size < 3:
        raise ShapeError(f"expected ranges and angles of one length >= 3, got {r.size}, {phi.size}")
    inc = float(phi[1] - phi[0])
    if not inc > 0 or not np.allclose(np.diff(phi), inc, rtol=1e-6, atol=1e-9):
        raise InputError("angles: expected evenly spaced, increasing beam angles")
    valid = np.isfinite(r) & (r > 0) & (r < cfg.max_range)
    far = np.where(valid, r, np.inf)  # no return counts as farther than anything
    out: list[tuple[float, float, float, int, bool]] = []
    for a, b in _runs(valid, np.where(valid, r, 0.0), cfg.jump):
        found = _trunk(r[a:b], phi[a:b], inc, cfg)
        if found is None or a == 0 or b == r.size:
            continue
        r_near = float(r[a:b].min())
        if not (far[a - 1] - r_near > cfg.jump and far[b] - r_near > cfg.jump):
            continue  # a nearer or touching neighbour: occluded, the width is not the trunk's
        out.append(found)
    arr = np.array(out, dtype=np.float64).reshape(-1, 5)
    return TreeDetections(
        ranges=arr[:, 0].copy(),
        bearings=arr[:, 1].copy(),
        diameters=arr[:, 2].copy(),
        beams=arr[:, 3].astype(np.int64),
        fitted=arr[:, 4].astype(bool),
    )


def _trunk(
    r: FloatArray, phi: FloatArray, inc: float, cfg: TreeExtractorConfig
) -> tuple[float, float, float, int, bool] | None:
    """One run of beams as a trunk ``(range, bearing, diameter, beams, fitted)``, or None."""
    n = r.size
    r_near = float(r.min())
    # Beams a trunk of the smallest and largest diameter gives at this range (±1 beam).
    half = np.array([cfg.min_diameter, cfg.max_diameter]) / 2.0
    span = 2.0 * np.arcsin(half / (r_near + half))  # Δφ = 2 asin(R / (r + R))
    if n + 1 < span[0] / inc or n - 1 > span[1] / inc:
        return None
    radius = float(_radius_from_width(np.array(r_near), np.array(n * inc)))
    tol = 3.0 * cfg.range_sigma
    r_wide = float(_radius_from_width(np.array(r_near), np.array((n + 1) * inc)))
    if float(r.max()) - r_near > r_wide + tol:
        return None  # deeper than a trunk as wide as the run can be
    if n > 2:
        chord = np.interp(phi, [phi[0], phi[-1]], [r[0], r[-1]])
        if np.any(r[1:-1] > chord[1:-1] + tol):
            return None  # bulges away from the laser: a corner, not a trunk
    bearing = float(0.5 * (phi[0] + phi[-1]))
    if n >= cfg.fit_beams:
        x, y = r * np.cos(phi), r * np.sin(phi)
        fit = _kasa_fit(x, y)
        if fit is not None:
            cx, cy, rad = fit
            d_c = float(np.hypot(cx, cy))
            if cfg.min_diameter <= 2 * rad <= cfg.max_diameter and d_c > r_near:
                return d_c, float(np.arctan2(cy, cx)), 2 * rad, n, True
    diameter = 2.0 * radius
    if not cfg.min_diameter <= diameter <= cfg.max_diameter:
        return None
    return r_near + radius, bearing, diameter, n, False
