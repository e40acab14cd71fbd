"""GPS fixes in EKF-SLAM: the antenna's position as a measurement of the pose, the χ² gate
against multipath, and the one-off move of the filter into the GPS frame.

**The measurement.** The antenna sits at ``o`` (the lever arm, robot frame: ahead, left), so
a fix measures ``h(x) = t + R(θ) o`` for the pose ``x = (t, θ)``. The EKF's state is
additive, so the Jacobian is the plain derivative::

    ∂h/∂t = I        ∂h/∂θ = R'(θ) o = S R(θ) o = (−(R o)_y, (R o)_x)

(``S`` the quarter turn: turning the truck swings the antenna about the reference point at
right angles to the arm). ``h`` does not depend on the map, so ``H = [H_r, 0, …, 0]`` and
``H Σ = H_r Σ[0:3, :]`` needs the pose's three rows only: the update reads and writes the
covariance once, as a landmark update does (:func:`~slamkit.slam.ekf_slam.update.
gain_update_inplace`, the Joseph form).

**The gate.** ``d² = νᵀ S⁻¹ ν`` of a good fix is χ² with 2 degrees of freedom; a fix above
``χ²₂(p)`` is refused (counted), its pull nil. A dropout is simply no fix.

**The frame.** A fix is in the GPS frame (east, north from the receiver's origin); the filter
starts in the frame of its first pose. Fixes are first collected beside the filter's own
antenna positions until they span :data:`ALIGN_SPAN` metres; the rigid SE(2) fit of the one
onto the other (:func:`~slamkit.geometry.alignment.align_points_2d`, once again without the
pairs more than 3σ off) then moves the whole state into the GPS frame
(:func:`move_state_inplace`: every position rotated and shifted, the heading turned, the
covariance ``J Σ Jᵀ``), and the fit's own uncertainty is added to the covariance as the
error every position shares (:func:`add_frame_uncertainty`). From then on each fix updates
the filter. The fixes spent on the fit are counted, not fused (their information is in the
frame).
"""

from __future__ import annotations

import math

import numpy as np

from slamkit._validation import FloatArray
from slamkit.estimation.contract import RunWarning, SmoothedTrajectory
from slamkit.estimation.gaussian import small_spd_inverse
from slamkit.geometry.alignment import align_points_2d
from slamkit.geometry.angles import wrap_angle
from slamkit.prob import chi2_gate
from slamkit.slam.ekf_slam.update import gain_update_inplace

__all__ = [
    "ALIGN_MIN_FIXES",
    "ALIGN_SPAN",
    "GPS_COUNTS",
    "REFUSED_SHARE",
    "FrameAligner",
    "GpsFusion",
    "add_frame_uncertainty",
    "antenna_measurement",
    "gps_update_inplace",
    "gps_warnings",
    "move_state_inplace",
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


def antenna_measurement(pose: FloatArray, lever: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``h = t + R(θ) o`` ``(2,)`` and ``∂h/∂(x, y, θ)`` ``(2, 3)`` for a pose ``(3,)`` and
    a lever arm ``o (2,)`` (module docstring)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rox = c * lever[0] - s * lever[1]  # R o
    roy = s * lever[0] + c * lever[1]
    h = np.array([pose[0] + rox, pose[1] + roy])
    H = np.array([[1.0, 0.0, -roy], [0.0, 1.0, rox]])
    return h, H


def gps_update_inplace(
    mean: FloatArray,
    cov: FloatArray,
    z: FloatArray,
    lever: FloatArray,
    R: FloatArray,
    gate: float,
    scratch: FloatArray,
) -> tuple[float, bool]:
    """Update the active state (``mean (n,)``, ``cov (n, n)``, pose first) with the fix
    ``z (2,)`` of covariance ``R (2, 2)`` unless its ``d²`` exceeds ``gate``; returns
    ``(d², used)``. ``scratch`` holds at least ``n`` numbers."""
    h, Hr = antenna_measurement(mean[:3], lever)
    nu = z - h
    HS = Hr @ cov[:3, :]  # H Σ: the map's blocks of H are zero
    S = HS[:, :3] @ Hr.T + R
    S = 0.5 * (S + S.T)
    S_inv = small_spd_inverse(S, "ekf-slam gps update")
    assert S_inv is not None  # 2 × 2
    d2 = float(nu @ S_inv @ nu)
    if not d2 <= gate:
        return d2, False
    # slot 0: only the gain's "consider" branch and the symmetrised block read it, and the
    # block at 0 lies inside the pose block, symmetrised anyway.
    gain_update_inplace(mean, cov, 0, nu, HS, S, scratch)
    return d2, True


def _position_rows(n: int) -> FloatArray:
    """Index pairs ``(P, 2)`` of the positions in a state of size ``n``: pose, landmarks."""
    starts = np.concatenate(([0], np.arange(3, n, 2)))
    return np.stack([starts, starts + 1], axis=1)


def move_state_inplace(mean: FloatArray, cov: FloatArray, angle: float, shift: FloatArray) -> None:
    """Move the state into another frame: every position ``p ← R(angle) p + shift``, the
    heading ``θ ← θ + angle`` (wrapped), the covariance ``Σ ← J Σ Jᵀ`` with ``J`` block
    diagonal (``R(angle)`` for each position, 1 for the heading)."""
    n = mean.shape[0]
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    rows = _position_rows(n)
    pts = mean[rows]  # (P, 2)
    mean[rows] = pts @ rot.T + shift
    mean[2] = (mean[2] + angle + math.pi) % (2.0 * math.pi) - math.pi
    J = np.eye(n)
    for a, b in rows:
        J[a : b + 1, a : b + 1] = rot
    cov[:, :] = J @ cov @ J.T  # once per run: a dense product is fine
    cov[:, :] = 0.5 * (cov + cov.T)


def add_frame_uncertainty(cov: FloatArray, mean: FloatArray, centre: FloatArray,
                          frame_cov: FloatArray) -> None:  # fmt: skip
    """``Σ ← Σ + A Σ_T Aᵀ``: the fitted frame's error ``δT = (δc, δφ)`` (a shift at
    ``centre`` and a turn about it, covariance ``frame_cov (3, 3)``) moves every position
    ``p`` by ``δc + δφ S (p − centre)`` and the heading by ``δφ``, so ``A``'s rows are
    ``[I, S (p − centre)]`` for a position and ``[0, 0, 1]`` for the heading."""
    n = mean.shape[0]
    A = np.zeros((n, 3))
    rows = _position_rows(n)
    d = mean[rows] - centre  # (P, 2)
    A[rows[:, 0], 0] = 1.0
    A[rows[:, 1], 1] = 1.0
    A[rows[:, 0], 2] = -d[:, 1]  # S d = (−d_y, d_x)
    A[rows[:, 1], 2] = d[:, 0]
    A[2, 2] = 1.0
    cov += A @ frame_cov @ A.T


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

    def fit(self) -> tuple[float, FloatArray, FloatArray, FloatArray]:
        """``(angle, shift, centre, frame_cov)``: ``p_gps = R(angle) p + shift`` fitted on the
        pairs (refitted without those more than 3σ off), ``centre`` the fitted pairs'
        centroid in the GPS frame and ``frame_cov`` the fit's covariance of ``(shift at the
        centre, angle)``: ``σ²/N`` per axis and ``σ² / Σ|p − centre|²``."""
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
        return sim.angle, np.asarray(sim.translation, dtype=float), centre, frame_cov


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


class GpsFusion:
    """A filter's GPS fusion, one object the estimator holds when its stream has fixes: the
    lever arm, the fixes' noise and gate, the move into the GPS frame, the counts, and the
    path kept to return it in the GPS frame (module docstring)."""

    def __init__(
        self, noise_cov: FloatArray, lever_arm: tuple[float, float], gate_probability: float,
        start_time: float, start_pose: FloatArray,
    ) -> None:  # fmt: skip
        self.counts = dict.fromkeys(GPS_COUNTS, 0)
        """How many fixes were seen, spent on the frame, fused, refused (:data:`GPS_COUNTS`)."""
        self._R = noise_cov
        self._lever = np.asarray(lever_arm, dtype=np.float64)
        self._gate = chi2_gate(2, gate_probability)
        self._aligner: FrameAligner | None = FrameAligner(math.sqrt(np.trace(noise_cov) / 2.0))
        # The pose at every time stamp; _moved: the move's angle, shift and how many of the
        # kept poses precede it (they are moved at the end).
        self._path_t: list[float] = [start_time]
        self._path: list[FloatArray] = [np.array(start_pose[:3], dtype=float)]
        self._moved: tuple[float, FloatArray, int] | None = None

    def fix(self, mean: FloatArray, cov: FloatArray, t: float, z: FloatArray,
            scratch: FloatArray) -> None:  # fmt: skip
        """The fix ``z`` at ``t`` on the active state: collected for the move into the GPS
        frame until that is done, then fused through the gate."""
        self.counts["gps_fixes"] += 1
        if self._aligner is not None:
            self.counts["gps_aligning"] += 1
            antenna, _ = antenna_measurement(mean[:3], self._lever)
            if self._aligner.add(antenna, z):
                angle, shift, centre, frame_cov = self._aligner.fit()
                move_state_inplace(mean, cov, angle, shift)
                add_frame_uncertainty(cov, mean, centre, frame_cov)
                self._aligner = None
                self._moved = (angle, shift, len(self._path_t) - int(self._path_t[-1] >= t))
            return
        _, used = gps_update_inplace(mean, cov, z, self._lever, self._R, self._gate, scratch)
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
        the state was); ``None`` if the filter never moved (its online path is all)."""
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
