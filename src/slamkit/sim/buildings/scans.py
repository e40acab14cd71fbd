"""Laser scans in a generated building: opaque walls, glass and walking people.

Per beam, at once for every scan (arrays ``(N, B)``):

* **walls and clutter** return the ray's first hit (:func:`~slamkit.models.cast_rays_segments`);
* **glass** returns only at times: a beam meeting a pane within 15° of its normal is
  reflected back with probability 0.9 (:data:`GLASS_RETURN_NORMAL`), at a more glancing
  angle with probability 0.1 (:data:`GLASS_RETURN_GLANCING`), drawn per beam and scan;
  otherwise it passes through to whatever opaque wall lies behind (a second pane behind the
  first is not seen; beyond an outer window there is nothing, so the beam reads max range).
  The panes are axis-aligned, so the angle of incidence follows from the beam's direction;
* **people** are circles (:class:`~slamkit.sim.buildings.plan.Walkers`) that occlude what
  lies behind them; a sensor inside a circle does not see that person;
* the reading is the nearest of these plus ``N(0, σ²)``, clipped to ``[0, max_range]``; a
  beam that meets nothing within ``max_range`` reads exactly ``max_range``.

The random numbers are drawn in a fixed order (the glass draws, then the range noise, both
``(N, B)``) whether or not there are people or glass, so leaving people out changes only the
beams they block.
"""

from __future__ import annotations

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import LaserSpec
from slamkit.models import cast_rays_segments
from slamkit.sim.buildings.plan import Building, Walkers

__all__ = ["GLASS_RETURN_GLANCING", "GLASS_RETURN_NORMAL", "simulate_building_scans"]

GLASS_RETURN_NORMAL = 0.9
"""Chance that glass returns a beam within :data:`GLASS_NORMAL_CONE` of its normal."""
GLASS_RETURN_GLANCING = 0.1
"""Chance that glass returns a beam at a more glancing angle."""
GLASS_NORMAL_CONE = np.deg2rad(15.0)
"""Half-angle [rad] of the near-normal cone of incidence."""


def simulate_building_scans(
    building: Building,
    poses: FloatArray,
    times: FloatArray,
    laser: LaserSpec,
    rng: np.random.Generator,
    *,
    people: bool = True,
) -> FloatArray:
    """Scans ``(N, B)`` from the laser at ``poses (N, 3)`` at ``times (N,)`` [s] (the people
    move with time; ``people=False`` leaves them out). The laser sits at the pose (its
    ``mounting`` is not applied)."""
    beams = laser.beam_angles
    rmax = laser.max_range
    glass_draw = rng.random((poses.shape[0], beams.size))
    noise = rng.standard_normal((poses.shape[0], beams.size)) * laser.range_sigma
    ranges = cast_rays_segments(poses, beams, building.walls, rmax)
    panes = building.glass.segments
    if panes.shape[0]:
        # The nearest pane of either orientation decides (one draw per beam).
        phi = poses[:, 2:3] + beams[None, :]
        horizontal = np.abs(panes[:, 0, 1] - panes[:, 1, 1]) < 1e-9
        hit_h = cast_rays_segments(poses, beams, panes[horizontal], rmax)
        hit_v = cast_rays_segments(poses, beams, panes[~horizontal], rmax)
        pane = np.minimum(hit_h, hit_v)
        cos_incidence = np.where(hit_h <= hit_v, np.abs(np.sin(phi)), np.abs(np.cos(phi)))
        p = np.where(cos_incidence >= np.cos(GLASS_NORMAL_CONE), GLASS_RETURN_NORMAL,
                     GLASS_RETURN_GLANCING)  # fmt: skip
        ranges = np.where((pane < ranges) & (glass_draw < p), pane, ranges)
    if people and building.walkers.ends.shape[0]:
        ranges = np.minimum(ranges, _people_ranges(poses, beams, building.walkers, times, rmax))
    noisy = np.clip(ranges + noise, 0.0, rmax)
    return np.where(ranges >= rmax, rmax, noisy)


def _people_ranges(
    poses: FloatArray, beams: FloatArray, walkers: Walkers, times: FloatArray, rmax: float
) -> FloatArray:
    """Range ``(N, B)`` along each beam to the nearest person (``rmax`` if none): the first
    root of ``|o + t d - c|² = r²``, ``t = d·w - √((d·w)² - |w|² + r²)`` with ``w = c - o``."""
    centres = walkers.positions(times)  # (N, P, 2)
    w = centres - poses[:, None, :2]  # (N, P, 2)
    phi = poses[:, 2:3] + beams[None, :]  # (N, B)
    d = np.stack([np.cos(phi), np.sin(phi)], axis=-1)  # (N, B, 2)
    dw = np.einsum("nbk,npk->nbp", d, w)
    ww = np.sum(w * w, axis=-1)[:, None, :]  # (N, 1, P)
    disc = dw * dw - ww + walkers.radius**2
    t = dw - np.sqrt(np.maximum(disc, 0.0))
    valid = (disc >= 0.0) & (t > 0.0) & (ww > walkers.radius**2)
    return np.where(valid, t, rmax).min(axis=-1, initial=rmax)
