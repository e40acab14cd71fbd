"""What every online filter does with a GPS fix before its own update: the antenna's position
as a measurement of the pose, the χ² gate against multipath, the one-off move into the GPS
frame, the counts and warnings, and the path returned in the GPS frame. EKF-SLAM (and
UKF-SLAM through it) and FastSLAM 1.0/2.0 stand on this module; each adds only how its own
belief takes a fix and moves (``slam/ekf_slam/gps.py``, ``slam/fastslam/gps.py``).

**The measurement.** The antenna sits at ``o`` (the lever arm, robot frame: ahead, left), so
a fix measures ``h(x) = t + R(θ) o`` for the pose ``x = (t, θ)``, with the derivative::

    ∂h/∂t = I        ∂h/∂θ = R'(θ) o = S R(θ) o = (−(R o)_y, (R o)_x)

(``S`` the quarter turn: turning the truck swings the antenna about the reference point at
right angles to the arm). ``h`` does not depend on the map.

**The gate.** ``d² = νᵀ S⁻¹ ν`` of a good fix, with ``S`` the covariance of the predicted
fix (the filter's pose uncertainty carried to the antenna, plus the fix's noise), is χ² with
2 degrees of freedom; a fix above ``χ²₂(p)`` is refused (counted), its pull nil. A dropout is
simply no fix.

**The frame.** A fix is in the GPS frame (east, north from the receiver's origin); a filter
starts in the frame of its first pose. Fixes are first collected beside the filter's own
antenna positions until they span :data:`ALIGN_SPAN` metres; the rigid SE(2) fit of the one
onto the other (:func:`~slamkit.geometry.alignment.align_points_2d`, once again without the
pairs more than 3σ off, :class:`FrameAligner`) then says how to move the whole belief into
the GPS frame, and how uncertain that move is (:class:`FrameFit`). The fixes spent on the fit
are counted, not fused (their information is in the frame). :class:`GpsFrontEnd` keeps the
counts and the path, so that the path before the move is returned moved too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import ConfigError
from slamkit.estimation.contract import RunWarning, SmoothedTrajectory
from slamkit.geometry.alignment import align_points_2d
from slamkit.geometry.angles import wrap_angle
from slamkit.prob import chi2_gate

__all__ = [
    "ALIGN_MIN_FIXES",
    "ALIGN_SPAN",
    "GPS_COUNTS",
    "REFUSED_SHARE",
    "FrameAligner",
    "FrameFit",
    "GpsFrontEnd",
    "antenna_measurement",
    "antenna_measurements",
    "check_gps_settings",
    "gps_warnings",
]

GPS_COUNTS = ("gps_fixes", "gps_aligning", "gps_fused", "gps_refused")
"""The counts of GPS fixes in a filter's diagnostics: all, spent on moving into the GPS frame,
fused, refused by the gate."""

ALIGN_SPAN = 50.0
"""The filter is moved into the GPS frame once its antenna positions at the collected fixes
span this many metres (the largest distance from the first): with σ = 1 m fixes the fitted
heading is then good to about 0.01 rad."""
ALIGN_MIN_FIXES = 10
"""And at least this many fixes were collected."""
REFUSED_SHARE = 0.5
"""A run whose gate refused more than this share of the fixes it judged gets a warning: the
filter and the GPS disagree for good (on Victoria Park with the lever arm left at 0, 3,695
of 3,883; with the graph's arm, 319: ``docs/estimators/gps.md``). A filter cannot re-weigh
a refused fix later, so once it drifts past the gate it stays there."""


def check_gps_settings(lever_arm: object, gate_probability: float) -> tuple[float, float]:
    """The settings ``gps_lever_arm`` (two finite numbers [m]) and ``gps_gate_probability``
    (``0 < p < 1``) of a filter's config, checked; returns the arm as a tuple of floats."""
    try:
        arm = tuple(float(v) for v in lever_arm)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        arm = ()
    if len(arm) != 2 or not all(math.isfinite(v) for v in arm):
        raise ConfigError(f"gps_lever_arm: expected two finite numbers [m], got {lever_arm!r}")
    if not 0.0 < gate_probability < 1.0:
        raise ConfigError(f"gps_gate_probability: expected 0 < p < 1, got {gate_probability}")
    return arm[0], arm[1]


def antenna_measurement(pose: FloatArray, lever: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``h = t + R(θ) o`` ``(2,)`` and ``∂h/∂(x, y, θ)`` ``(2, 3)`` for a pose ``(3,)`` and
    a lever arm ``o (2,)`` (module docstring)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rox = c * lever[0] - s * lever[1]  # R o
    roy = s * lever[0] + c * lever[1]
    h = np.array([pose[0] + rox, pose[1] + roy])
    H = np.array([[1.0, 0.0, -roy], [0.0, 1.0, rox]])
    return h, H


def antenna_measurements(poses: FloatArray, lever: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`antenna_measurement` of many poses ``(P, 3)``: ``h (P, 2)``, ``H (P, 2, 3)``."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    rox = c * lever[0] - s * lever[1]
    roy = s * lever[0] + c * lever[1]
    h = np.stack([poses[:, 0] + rox, poses[:, 1] + roy], axis=1)
    H = np.zeros((poses.shape[0], 2, 3))
    H[:, 0, 0] = H[:, 1, 1] = 1.0
    H[:, 0, 2] = -roy
    H[:, 1, 2] = rox
    return h, H


@dataclass(frozen=True)
class FrameFit:
    """The move of a filter into the GPS frame, ``p_gps = R(angle) p + shift``, and its
    uncertainty: ``cov (3, 3)`` of the error ``(δc, δφ)`` — a shift at ``centre`` (the fitted
    pairs' centroid in the GPS frame) and a turn about it — that every position shares."""

    angle: float
    shift: FloatArray
    centre: FloatArray
    cov: FloatArray


class FrameAligner:
    """Collects ``(antenna estimate, fix)`` pairs until they span :data:`ALIGN_SPAN` m,
    then fits the filter's frame to the GPS frame (module docstring)."""

    def __init__(self, sigma: float) -> None:
        self.sigma = sigma
        """The fixes' standard deviation [m] (per axis)."""
        self._est: list[FloatArray] = []
        self._fix: list[FloatArray] = []

    def add(self, antenna: FloatArray, fix: FloatArray) -> bool:
        """Add one pair; ``True`` once enough are collected to fit."""
        self._est.append(np.array(antenna, dtype=float))
        self._fix.append(np.array(fix, dtype=float))
        if len(self._est) < ALIGN_MIN_FIXES:
            return False
        est = np.asarray(self._est)
        return float(np.max(np.linalg.norm(est - est[0], axis=1))) >= ALIGN_SPAN

    def fit(self) -> FrameFit:
        """The frame fitted on the pairs (refitted without those more than 3σ off); its
        covariance: ``σ²/N`` per axis for the shift at the centre, ``σ² / Σ|p − centre|²``
        for the angle."""
        est, fix = np.asarray(self._est), np.asarray(self._fix)
        keep = np.ones(est.shape[0], dtype=bool)
        for _ in range(2):
            sim = align_points_2d(est[keep], fix[keep])
            resid = np.linalg.norm(sim.apply_to_points(est) - fix, axis=1)
            keep = resid <= 3.0 * self.sigma
            if keep.sum() < 3:  # too few agree: keep every pair
                keep[:] = True
        sim = align_points_2d(est[keep], fix[keep])
        moved = sim.apply_to_points(est[keep])
        centre = moved.mean(axis=0)
        spread = float(np.sum((moved - centre) ** 2))
        var = self.sigma**2
        frame_cov = np.diag([var / keep.sum(), var / keep.sum(), var / max(spread, 1e-9)])
        return FrameFit(sim.angle, np.asarray(sim.translation, dtype=float), centre, frame_cov)


def gps_warnings(counts: dict[str, int]) -> tuple[RunWarning, ...]:
    """The run's doubts about its GPS, from the counts ``gps_fixes``, ``gps_aligning``,
    ``gps_fused``, ``gps_refused``: never moved into the GPS frame, or the gate refused
    most fixes (:data:`REFUSED_SHARE`)."""
    if not counts["gps_fixes"]:
        return ()
    judged = counts["gps_fused"] + counts["gps_refused"]
    if not judged:
        return (
            RunWarning(
                "gps_not_used",
                f"the {counts['gps_fixes']} GPS fixes never spanned {ALIGN_SPAN:g} m of the "
                "path, so the filter never moved into the GPS frame and fused none",
            ),
        )
    if counts["gps_refused"] > REFUSED_SHARE * judged:
        return (
            RunWarning(
                "gps_refused",
                f"the χ² gate refused {counts['gps_refused']} of {judged} GPS fixes: the "
                "filter and the GPS disagree (is gps_lever_arm right?), so the path follows "
                "the odometry and the landmarks",
            ),
        )
    return ()


class GpsFrontEnd:
    """The part of a filter's GPS fusion that does not depend on its belief: the lever arm,
    the fixes' noise and gate, collecting the fixes for the move into the GPS frame, the
    counts, and the path kept to return it in the GPS frame. A filter calls :meth:`collect`
    while :attr:`aligned` is false (and moves its belief by the fit it returns), then
    updates its belief itself and reports each verdict to :meth:`judged`; it calls
    :meth:`record` after every event."""

    def __init__(
        self, noise_cov: FloatArray, lever_arm: tuple[float, float], gate_probability: float,
        start_time: float, start_pose: FloatArray,
    ) -> None:  # fmt: skip
        self.counts = dict.fromkeys(GPS_COUNTS, 0)
        """How many fixes were seen, spent on the frame, fused, refused (:data:`GPS_COUNTS`)."""
        self.noise_cov = np.asarray(noise_cov, dtype=np.float64)
        """The fixes' covariance ``R (2, 2)`` [m²]."""
        self.lever = np.asarray(lever_arm, dtype=np.float64)
        """The lever arm ``o (2,)`` [m]."""
        self.gate = chi2_gate(2, gate_probability)
        """The largest ``d²`` of a fix that is fused."""
        self._aligner: FrameAligner | None = FrameAligner(math.sqrt(np.trace(noise_cov) / 2.0))
        # The pose at every time stamp; _moved: the move's angle, shift and how many of the
        # kept poses precede it (they are moved at the end).
        self._path_t: list[float] = [start_time]
        self._path: list[FloatArray] = [np.array(start_pose[:3], dtype=float)]
        self._moved: tuple[float, FloatArray, int] | None = None

    @property
    def aligned(self) -> bool:
        """Whether the filter has moved into the GPS frame (fixes are judged from then on)."""
        return self._aligner is None

    def collect(self, t: float, z: FloatArray, pose: FloatArray) -> FrameFit | None:
        """The fix ``z`` at ``t`` beside the filter's pose ``(3,)`` (its antenna), for the
        move into the GPS frame; the fit once enough fixes are collected (the filter then
        moves its belief by it, and its earlier path is moved at the end)."""
        assert self._aligner is not None  # called only before the move
        self.counts["gps_fixes"] += 1
        self.counts["gps_aligning"] += 1
        antenna, _ = antenna_measurement(pose, self.lever)
        if not self._aligner.add(antenna, z):
            return None
        fit = self._aligner.fit()
        self._aligner = None
        self._moved = (fit.angle, fit.shift, len(self._path_t) - int(self._path_t[-1] >= t))
        return fit

    def judged(self, used: bool) -> None:
        """Count a fix the gate let through (``used``) or refused."""
        self.counts["gps_fixes"] += 1
        self.counts["gps_fused" if used else "gps_refused"] += 1

    def record(self, t: float, pose: FloatArray) -> None:
        """The pose ``(3,)`` after an event at ``t`` (the last one of a stamp is kept)."""
        if t > self._path_t[-1]:
            self._path_t.append(t)
            self._path.append(np.array(pose, dtype=float))
        else:
            self._path[-1] = np.array(pose, dtype=float)

    def trajectory(self) -> SmoothedTrajectory | None:
        """The path at every time stamp in the GPS frame (the poses before the move moved as
        the belief was); ``None`` if the filter never moved (its online path is all)."""
        if self._moved is None:
            return None
        angle, shift, n = self._moved
        path = np.asarray(self._path)
        early = path[:n].copy()
        c, s = math.cos(angle), math.sin(angle)
        path[:n, 0] = c * early[:, 0] - s * early[:, 1] + shift[0]
        path[:n, 1] = s * early[:, 0] + c * early[:, 1] + shift[1]
        path[:n, 2] = wrap_angle(early[:, 2] + angle)
        return SmoothedTrajectory(np.asarray(self._path_t), path)
