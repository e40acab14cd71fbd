"""Trajectory accuracy: timestamp association, pose errors, ATE and RPE for SE(2) paths.

* :func:`associate` pairs two timestamp streams (estimate and ground truth).
* :func:`pose_errors` is the one definition of the state error of an SE(2) pose,
  ``(x̂ − x, ŷ − y, wrap(θ̂ − θ))``; NEES and every metric below build on it.
* :func:`absolute_trajectory_error` (ATE) measures global consistency after removing the
  arbitrary choice of world frame (least-squares SE(2) alignment, first-pose alignment or none).
* :func:`relative_pose_error` (RPE) measures local drift: how wrong the estimated motion
  between two poses a fixed number of frames or metres apart is, independently of any world
  frame.

Everything is array-in / result-object-out; nothing here plots or prints.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.errors import ConfigError, InputError, ShapeError
from slamkit.geometry.alignment import Similarity, align_points_2d
from slamkit.geometry.angles import angle_diff
from slamkit.geometry.pose2 import between, compose, inverse

__all__ = [
    "AlignMode",
    "RelativeError",
    "RpeUnit",
    "TrajectoryError",
    "absolute_trajectory_error",
    "associate",
    "pose_errors",
    "relative_pose_error",
]

AlignMode = Literal["se2", "origin", "none"]
RpeUnit = Literal["frames", "meters"]
IndexArray = NDArray[np.int64]

_ALIGN_MODES: tuple[str, ...] = ("se2", "origin", "none")
_RPE_UNITS: tuple[str, ...] = ("frames", "meters")


# --------------------------------------------------------------------------- helpers
@dataclass(frozen=True)
class _Summary:
    rmse: float
    mean: float
    median: float
    max: float
    std: float


def error_summary(values: FloatArray) -> _Summary:
    """RMSE, mean, median, max and (population) standard deviation of non-empty ``values``."""
    assert values.size > 0, "callers reject empty inputs"
    return _Summary(
        rmse=float(np.sqrt(np.mean(values**2))),
        mean=float(np.mean(values)),
        median=float(np.median(values)),
        max=float(np.max(values)),
        std=float(np.std(values)),
    )


def _pose_pair(estimate: ArrayLike, truth: ArrayLike) -> tuple[FloatArray, FloatArray]:
    est = as_array(estimate, "estimate", (None, 3))
    tru = as_array(truth, "truth", (None, 3))
    if est.shape != tru.shape:
        raise ShapeError(
            f"estimate and truth: expected the same number of poses, got {est.shape[0]} and "
            f"{tru.shape[0]} (use associate() to pair them by timestamp)"
        )
    if est.shape[0] == 0:
        raise InputError("estimate: expected at least one pose, got none")
    return est, tru


# ------------------------------------------------------------------------ association
def associate(
    times_a: ArrayLike, times_b: ArrayLike, max_dt: float
) -> tuple[IndexArray, IndexArray]:
    """Pair each time in ``times_a (N,)`` with the nearest time in ``times_b (M,)``.

    Returns index arrays ``(idx_a, idx_b)`` of equal length ``K``: ``times_a[idx_a[k]]`` is
    matched with ``times_b[idx_b[k]]`` and ``|Δt| ≤ max_dt``. ``idx_a`` is increasing; times in
    ``a`` with no partner within ``max_dt`` are dropped. Neither stream needs to be sorted.

    Behaviour to know: every ``a`` is used at most once, but the matching is not one-to-one
    in ``b`` — when ``a`` is sampled faster than ``b``, several ``a`` can share the same
    ``b``. With ``max_dt`` below half the sampling period of both streams the pairs are
    one-to-one. On an exact tie the earlier ``b`` wins. Vectorised: ``O((N + M) log M)``.
    """
    ta = as_array(times_a, "times_a", (None,))
    tb = as_array(times_b, "times_b", (None,))
    dt_max = float(max_dt)
    if not (np.isfinite(dt_max) and dt_max >= 0):
        raise InputError(f"max_dt: expected a finite number >= 0, got {max_dt!r}")
    empty = np.zeros(0, dtype=np.int64)
    if ta.size == 0 or tb.size == 0:
        return empty, empty.copy()
    order = np.argsort(tb, kind="stable")
    tb_sorted = tb[order]
    right = np.clip(np.searchsorted(tb_sorted, ta, side="left"), 0, tb.size - 1)
    left = np.clip(right - 1, 0, tb.size - 1)
    d_left = np.abs(ta - tb_sorted[left])
    d_right = np.abs(ta - tb_sorted[right])
    best = np.where(d_left <= d_right, left, right)
    keep = np.minimum(d_left, d_right) <= dt_max
    idx_a = np.flatnonzero(keep).astype(np.int64)
    idx_b = order[best[keep]].astype(np.int64)
    return idx_a, idx_b


# ---------------------------------------------------------------------- pose errors
def pose_errors(estimate: ArrayLike, truth: ArrayLike) -> FloatArray:
    """State error of SE(2) poses ``(..., 3)``: ``(x̂ − x, ŷ − y, wrap(θ̂ − θ))``.

    This is the one place slamkit defines the error of a pose estimate (world-frame position
    difference, heading difference wrapped to ``[-pi, pi)``). Shapes must be equal.
    """
    est = as_array(estimate, "estimate", (..., 3))
    tru = as_array(truth, "truth", (..., 3))
    if est.shape != tru.shape:
        raise ShapeError(f"truth: expected the shape of estimate {est.shape}, got {tru.shape}")
    return np.concatenate(
        [est[..., :2] - tru[..., :2], angle_diff(est[..., 2], tru[..., 2])[..., None]], axis=-1
    )


# ------------------------------------------------------------------------------- ATE
@dataclass(frozen=True, eq=False)
class TrajectoryError:
    """Absolute trajectory error of an estimate against ground truth.

    Translational statistics are over the per-pose position errors ``‖p̂_i − p_i‖`` (metres)
    after applying :attr:`alignment` to the estimate; heading errors are signed, wrapped,
    in radians.
    """

    align: str
    """How the estimate was aligned: ``"se2"``, ``"origin"`` or ``"none"``."""
    alignment: Similarity
    """The 2-D transform applied to the estimate before comparing (identity for ``"none"``)."""
    aligned_estimate: FloatArray
    """The estimate after alignment, ``(N, 3)``."""
    translation_errors: FloatArray
    """Position error of each pose, ``(N,)`` metres."""
    heading_errors: FloatArray
    """Signed heading error ``wrap(θ̂ − θ)`` of each pose, ``(N,)`` radians."""
    rmse: float
    mean: float
    median: float
    max: float
    std: float
    heading_rmse: float
    """Root mean square of :attr:`heading_errors`, radians."""

    @property
    def count(self) -> int:
        """Number of compared poses."""
        return int(self.translation_errors.size)

    def as_dict(self) -> dict[str, float | int | str]:
        """The summary as plain Python values (JSON-ready); arrays are left out."""
        out: dict[str, float | int | str] = {
            "align": self.align,
            "count": self.count,
            "rmse": self.rmse,
            "mean": self.mean,
            "median": self.median,
            "max": self.max,
            "std": self.std,
            "heading_rmse": self.heading_rmse,
            "alignment_tx": float(self.alignment.translation[0]),
            "alignment_ty": float(self.alignment.translation[1]),
            "alignment_angle": self.alignment.angle,
            "alignment_scale": self.alignment.scale,
        }
        return out


def absolute_trajectory_error(
    estimate: ArrayLike,
    truth: ArrayLike,
    align: AlignMode = "se2",
    weights: ArrayLike | None = None,
) -> TrajectoryError:
    """ATE of an estimated path ``(N, 3)`` against the true one ``(N, 3)`` (same timestamps).

    ``align``:

    * ``"se2"`` — the rotation and translation minimising ``Σ w_i ‖R p̂_i + t − p_i‖²`` over
      the positions (:func:`~slamkit.geometry.alignment.align_points`); ``weights (N,)``
      optional. Needs at least two distinct positions.
    * ``"origin"`` — the rigid transform ``T = T_0 ⊕ (⊖T̂_0)`` that maps the first estimated
      pose exactly onto the first true pose (what a filter started at the true pose should
      need: the identity).
    * ``"none"`` — compare as given.
    """
    est, tru = _pose_pair(estimate, truth)
    if align not in _ALIGN_MODES:
        raise ConfigError(f"align: expected one of {', '.join(_ALIGN_MODES)}, got {align!r}")
    if weights is not None and align != "se2":
        raise ConfigError(f"weights: only used with align='se2', got align={align!r}")
    if align == "se2":
        alignment = align_points_2d(est[:, :2], tru[:, :2], weights=weights)
    elif align == "origin":
        alignment = Similarity.from_pose(compose(tru[0], inverse(est[0])))
    else:
        alignment = Similarity.identity(2)
    aligned = alignment.apply_to_poses(est)
    err = pose_errors(aligned, tru)
    trans = np.hypot(err[:, 0], err[:, 1])
    head = err[:, 2]
    s = error_summary(trans)
    return TrajectoryError(
        align=align,
        alignment=alignment,
        aligned_estimate=aligned,
        translation_errors=trans,
        heading_errors=head,
        rmse=s.rmse,
        mean=s.mean,
        median=s.median,
        max=s.max,
        std=s.std,
        heading_rmse=float(np.sqrt(np.mean(head**2))),
    )


# ------------------------------------------------------------------------------- RPE
@dataclass(frozen=True, eq=False)
class RelativeError:
    """Relative pose error over pose pairs ``(i, j)``.

    For each pair the error is the pose ``E = between(ΔT, ΔT̂) = ⊖ΔT ⊕ ΔT̂`` with the true
    relative motion ``ΔT = between(T_i, T_j)`` and the estimated one
    ``ΔT̂ = between(T̂_i, T̂_j)``: where the estimated motion ends, seen from where the true
    motion ends (the identity for a perfect estimate). Translational errors
    are ``‖E_xy‖`` (metres), rotational errors ``|E_θ|`` (radians).
    """

    delta: float
    unit: str
    pairs: IndexArray
    """Index pairs ``(K, 2)`` as ``(i, j)``."""
    errors: FloatArray
    """The error poses ``E`` ``(K, 3)``."""
    translation_errors: FloatArray
    rotation_errors: FloatArray
    translation_rmse: float
    translation_mean: float
    translation_median: float
    translation_max: float
    rotation_rmse: float
    rotation_mean: float
    rotation_median: float
    rotation_max: float

    @property
    def count(self) -> int:
        """Number of pose pairs."""
        return int(self.pairs.shape[0])

    def as_dict(self) -> dict[str, float | int | str]:
        """The summary as plain Python values (JSON-ready); arrays are left out."""
        return {
            "delta": self.delta,
            "unit": self.unit,
            "count": self.count,
            "translation_rmse": self.translation_rmse,
            "translation_mean": self.translation_mean,
            "translation_median": self.translation_median,
            "translation_max": self.translation_max,
            "rotation_rmse": self.rotation_rmse,
            "rotation_mean": self.rotation_mean,
            "rotation_median": self.rotation_median,
            "rotation_max": self.rotation_max,
        }


def _rpe_pairs(truth: FloatArray, delta: float, unit: str) -> IndexArray:
    n = truth.shape[0]
    try:
        d = float(delta)
    except (TypeError, ValueError) as exc:
        raise InputError(f"delta: expected a number, got {delta!r}") from exc
    if unit == "frames":
        if not (np.isfinite(d) and d == int(d) and d >= 1):
            raise InputError(f"delta: expected a whole number of frames >= 1, got {delta!r}")
        i = np.arange(max(n - int(d), 0), dtype=np.int64)
        j = i + int(d)
    else:
        if not (np.isfinite(d) and d > 0):
            raise InputError(f"delta: expected a distance in metres > 0, got {delta!r}")
        # cum[k] = distance travelled along the TRUE path from pose 0 to pose k.
        steps = np.hypot(*np.diff(truth[:, :2], axis=0).T)
        cum = np.concatenate([[0.0], np.cumsum(steps)])
        # First j with cum[j] >= cum[i] + delta (j > i because delta > 0).
        j_all = np.searchsorted(cum, cum + d, side="left")
        i = np.flatnonzero(j_all < n).astype(np.int64)
        j = j_all[i].astype(np.int64)
    return np.stack([i, j], axis=-1)


def relative_pose_error(
    estimate: ArrayLike,
    truth: ArrayLike,
    delta: float = 1,
    unit: RpeUnit = "frames",
) -> RelativeError:
    """RPE of an estimated path ``(N, 3)`` against the true one ``(N, 3)``.

    Pairs: with ``unit="frames"`` every ``(i, i + delta)``; with ``unit="meters"`` every ``i``
    paired with the first ``j`` whose distance travelled along the *true* path from ``i`` is
    at least ``delta`` metres (pairs overlap; ``i`` without such a ``j`` are dropped). See
    :class:`RelativeError` for the error definition. No alignment is needed: relative motions
    do not depend on the world frame.
    """
    est, tru = _pose_pair(estimate, truth)
    if unit not in _RPE_UNITS:
        raise ConfigError(f"unit: expected one of {', '.join(_RPE_UNITS)}, got {unit!r}")
    pairs = _rpe_pairs(tru, delta, unit)
    if pairs.shape[0] == 0:
        raise InputError(
            f"relative_pose_error: no pose pair is {delta} {unit} apart in a trajectory of "
            f"{tru.shape[0]} poses"
        )
    i, j = pairs[:, 0], pairs[:, 1]
    err = between(between(tru[i], tru[j]), between(est[i], est[j]))
    trans = np.hypot(err[:, 0], err[:, 1])
    rot = np.abs(err[:, 2])
    st, sr = error_summary(trans), error_summary(rot)
    return RelativeError(
        delta=float(delta),
        unit=unit,
        pairs=pairs,
        errors=err,
        translation_errors=trans,
        rotation_errors=rot,
        translation_rmse=st.rmse,
        translation_mean=st.mean,
        translation_median=st.median,
        translation_max=st.max,
        rotation_rmse=sr.rmse,
        rotation_mean=sr.mean,
        rotation_median=sr.median,
        rotation_max=sr.max,
    )
