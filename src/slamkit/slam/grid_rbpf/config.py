"""Settings of the grid-based Rao-Blackwellized particle filter (:mod:`.estimator`).

Twenty at most (issue 32): what a user of another laser, another robot or another building
may need to change. The constants that needed no tuning live beside the code that uses them
(the match's steps and tolerances, the stencil, the mode proposal's noise, the motion
floors, the recovery's window, the tiles, the resampling rule); the settings removed on
2026-12-07 are named in :data:`slamkit.config.RENAMED`, with
``docs/estimators/grid_rbpf.md`` ("Settings") saying why."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

from slamkit.config import (
    Section,
    finite_above,
    finite_at_least,
    fraction,
    int_at_least,
    setting,
)

__all__ = ["GridRbpfConfig"]


@dataclass(frozen=True)
class GridRbpfConfig(Section):
    """Settings of :class:`~slamkit.slam.grid_rbpf.GridRbpf`. Metres, degrees where named."""

    SECTION: ClassVar[str] = ""

    particles: int = setting(30, int_at_least(1), "an integer >= 1")
    """Number of particles (each a pose, a path and a map)."""
    proposal: Literal["gaussian", "mode"] = "gaussian"
    """``"gaussian"``: the improved proposal of Grisetti et al. (2007) — a Gaussian fitted
    to ``p(z | x, m) p(x | x', u)`` at a stencil of poses around the scan-match mode, the
    weight multiplied by its normaliser ``η``; ``"mode"``: GMapping's released behaviour —
    the mode plus small noise (1 cm, 0.3°), weighted by the likelihood there."""
    update_distance: float = setting(0.5, finite_at_least(0.0), "a finite number >= 0")
    """The filter updates once the odometry reports this much travel since the last
    update [m] ..."""
    update_angle_deg: float = setting(25.0, finite_at_least(0.0), "a finite number >= 0")
    """... or this much turning [deg]; scans in between are not used."""
    resolution: float = setting(0.05, finite_above(0.0), "a finite number > 0")
    """Grid cell side [m]."""
    max_range: float = setting(20.0, finite_above(0.0), "a finite number > 0")
    """Readings beyond this [m] are left out of matching and weighting, and (with max-range
    readings) clear free space only up to it; the likelihood field of a particle's map is
    built over the box of the remaining end points (+ 1 m)."""
    sigma_hit: float = setting(0.05, finite_above(0.0), "a finite number > 0")
    """Standard deviation of an end point's distance to the nearest wall [m] (likelihood
    field, for the match and the weights)."""
    likelihood_temperature: float = setting(10.0, finite_at_least(1.0), "a number >= 1")
    """``log p(z | x, m)`` is divided by this in the weights (and in the recovery's choice):
    the beams of one scan are far from independent (neighbouring beams see the same wall),
    and without tempering one particle takes all the weight at every update. The Gaussian
    fitted as the proposal uses the likelihood as it is, so that the draws stay as close to
    the match as the scan allows."""
    beam_stride: int = setting(2, int_at_least(1), "an integer >= 1")
    """Every this-th beam is used for matching and weighting."""
    motion_trans_per_m: float = setting(0.1, finite_at_least(0.0), "a finite number >= 0")
    """Motion model: position std per metre travelled [m/m] ..."""
    motion_trans_per_rad: float = setting(0.05, finite_at_least(0.0), "a finite number >= 0")
    """... per radian turned [m/rad];"""
    motion_rot_per_m: float = setting(0.05, finite_at_least(0.0), "a finite number >= 0")
    """heading std per metre travelled [rad/m] ..."""
    motion_rot_per_rad: float = setting(0.1, finite_at_least(0.0), "a finite number >= 0")
    """... per radian turned [rad/rad] (plus floors of 1 cm and 0.5°,
    :data:`~slamkit.slam.grid_rbpf.proposal.MOTION_FLOOR`)."""
    max_correction_xy: float = setting(0.5, finite_above(0.0), "a finite number > 0")
    """A match farther than this from the particle's prediction [m] counts as failed (the
    motion model is sampled instead) ..."""
    max_correction_deg: float = setting(15.0, finite_above(0.0), "a finite number > 0")
    """... or turned more than this [deg]."""
    recovery_score: float = setting(0.5, fraction(), "a fraction in [0, 1]")
    """A match whose score (mean per-beam likelihood relative to a perfect hit) is below
    this, or that failed or was gated, may have stopped in a local optimum near a wrong
    prediction (wheels that slipped): the scan is then also registered by a correlative
    search of ± 0.5 m, ± 30° around the prediction (``RECOVERY_SEARCH`` of
    :mod:`slamkit.slam.grid_rbpf.estimator`, refined by the same Gauss-Newton match), and
    whichever of the two poses has the larger
    ``log p(z | x, m) / likelihood_temperature + log p(x | x', u)`` is the proposal's mode;
    0: never."""
    min_range: float = setting(0.05, finite_at_least(0.0), "a finite number >= 0")
    """Readings at or below this [m] are dropped."""
    mounting: tuple[float, float, float] | None = None
    """The laser's pose in the robot frame; None: the data set's."""
    snapshots: int = setting(10, int_at_least(0), "an integer >= 0")
    """Particle snapshots kept for plots (spread over the run)."""
