"""The relation metric of the Freiburg laser SLAM benchmark (Kümmerle et al., "On measuring
the accuracy of SLAM algorithms", Autonomous Robots 27(4), 2009).

A reference relation ``(t1, t2, δ)`` (:class:`~slamkit.datasets.Relations`) is the pose of
the robot at ``t2`` in its own (base) frame at ``t1``. An estimated trajectory of world poses
``x̂(t) = T_world_robot(t)`` gives the same relative pose as

    δ̂ = between(x̂(t1), x̂(t2)) = x̂(t1)⁻¹ ⊕ x̂(t2),

and the error of the relation is the paper's ``δ̂ ⊖ δ`` with ``a ⊖ b = b⁻¹ ⊕ a`` (the inverse
of head-to-tail compounding, as in :func:`~slamkit.geometry.pose2.between`):

    e = δ⁻¹ ⊕ δ̂ = between(δ, δ̂) = (R(θ)ᵀ (t̂ − t), wrap(θ̂ − θ)),

where the estimated motion ends, seen from where the reference motion ends (the identity for
a perfect estimate). Its translational error is ``‖e_xy‖ = ‖t̂ − t‖`` (a rotation keeps
lengths, so the order of the two relative poses does not change it, nor does writing
``δ̂⁻¹ ⊕ δ``), its rotational error ``|wrap(θ̂ − θ)|``. Both only involve relative poses, so
they do not depend on the world frame of the estimate: moving the whole trajectory by one
rigid transform, or starting it with another heading, leaves every error unchanged.

(Cartographer's ``compute_relations_metrics`` uses ``δ̂ ⊕ δ⁻¹`` instead, whose translation
``t̂ − R(θ̂ − θ) t`` differs from ours by at most ``2 |sin((θ̂ − θ)/2)| ‖t‖``: the same
numbers when the rotational errors are small.)

**Poses at the stamps** (*covered* stamps). A relation stamp ``s`` takes

1. the trajectory's pose at ``s`` when a sample lies within ``stamp_tol`` of it (default
   :data:`STAMP_TOLERANCE`, 10 µs: the benchmark's files give stamps to the microsecond, a
   float64 epoch stamp resolves ~0.1 µs);
2. otherwise the interpolation (:func:`~slamkit.geometry.pose2.interpolate_poses`: position
   linearly, heading along the shorter arc) between the samples just before and just after
   ``s`` when *both* lie within ``max_gap`` seconds of ``s`` (default
   :data:`DEFAULT_MAX_GAP`, 1 s); a gap in the trajectory is not bridged;
3. otherwise nothing: the stamp is not covered (outside the trajectory, or in a gap).

A relation is scored when both its stamps are covered; ``covered_fraction`` says how many
were. The summary follows the published tables: mean ± standard deviation of the absolute
translational error [m] and of the absolute rotational error [deg], plus the means of the
squared errors [m², deg²] (the two terms of the paper's ε). Standard deviations are the
sample ones (``n − 1``; 0 for one relation), as in the Cartographer figures.

Numerics only; :mod:`slamkit.viz.relations` plots the per-relation errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_positive
from slamkit.datasets.relations import Relations
from slamkit.errors import InputError
from slamkit.geometry.pose2 import between, interpolate_poses

__all__ = [
    "DEFAULT_MAX_GAP",
    "STAMP_TOLERANCE",
    "RelationError",
    "poses_at_stamps",
    "relation_errors",
    "select_relations",
]

BoolArray = NDArray[np.bool_]

STAMP_TOLERANCE = 1e-5
"""[s] A trajectory sample this close to a relation stamp is the pose at that stamp."""
DEFAULT_MAX_GAP = 1.0
"""[s] A stamp between two samples is interpolated when both lie within this of it."""


@dataclass(frozen=True, eq=False)
class RelationError:
    """The relation metric of a trajectory against ``total`` reference relations.

    Per scored relation (``count`` of them, those whose two stamps the trajectory covers, in
    the order of the relations): :attr:`t1`, :attr:`t2`, the error poses :attr:`errors`
    ``e = δ⁻¹ ⊕ δ̂``, :attr:`translation_errors` ``‖e_xy‖`` [m] and
    :attr:`rotation_errors_deg` ``|e_θ|`` [deg]. :attr:`covered` ``(total,)`` marks the
    scored relations among the ones given (after ``max_duration``)."""

    t1: FloatArray
    """``(count,)`` first stamp of each scored relation [s]."""
    t2: FloatArray
    """``(count,)`` second stamp [s]."""
    errors: FloatArray
    """``(count, 3)`` error poses ``(x [m], y [m], θ [rad])``."""
    translation_errors: FloatArray
    """``(count,)`` ``‖e_xy‖`` [m]."""
    rotation_errors_deg: FloatArray
    """``(count,)`` ``|wrap(e_θ)|`` [deg]."""
    covered: BoolArray
    """``(total,)`` whether each given relation had both stamps covered (and was scored)."""
    translation_mean: float
    """Mean absolute translational error [m]."""
    translation_std: float
    """Sample standard deviation of the absolute translational errors [m]."""
    rotation_mean_deg: float
    """Mean absolute rotational error [deg]."""
    rotation_std_deg: float
    """Sample standard deviation of the absolute rotational errors [deg]."""
    translation_sq_mean: float
    """Mean squared translational error [m²]."""
    rotation_sq_mean_deg: float
    """Mean squared rotational error [deg²]."""
    translation_max: float
    """Largest translational error [m]."""
    rotation_max_deg: float
    """Largest rotational error [deg]."""
    max_gap: float
    """[s] The interpolation rule's limit the errors were computed with."""
    max_duration: float | None = None
    """[s] Only relations with ``|t2 − t1|`` at most this were given, if set."""

    @property
    def count(self) -> int:
        """Number of scored relations."""
        return int(self.translation_errors.size)

    @property
    def total(self) -> int:
        """Number of relations given (after ``max_duration``)."""
        return int(self.covered.size)

    @property
    def covered_fraction(self) -> float:
        """Fraction of the given relations whose two stamps the trajectory covers."""
        return self.count / self.total

    def as_dict(self) -> dict[str, float | int | None]:
        """The summary as plain Python values (JSON-ready); arrays are left out."""
        return {
            "count": self.count,
            "total": self.total,
            "covered_fraction": self.covered_fraction,
            "translation_mean": self.translation_mean,
            "translation_std": self.translation_std,
            "rotation_mean_deg": self.rotation_mean_deg,
            "rotation_std_deg": self.rotation_std_deg,
            "translation_sq_mean": self.translation_sq_mean,
            "rotation_sq_mean_deg": self.rotation_sq_mean_deg,
            "translation_max": self.translation_max,
            "rotation_max_deg": self.rotation_max_deg,
            "max_gap": self.max_gap,
            "max_duration": self.max_duration,
        }

    def summary(self) -> str:
        """One line in the published tables' form, e.g.
        ``0.220 ± 0.296 m, 1.3 ± 4.7°, 100 % covered``."""
        return (
            f"{self.translation_mean:.3f} ± {self.translation_std:.3f} m, "
            f"{self.rotation_mean_deg:.1f} ± {self.rotation_std_deg:.1f}°, "
            f"{100 * self.covered_fraction:.0f} % covered"
        )


def select_relations(
    relations: Relations,
    *,
    max_duration: float | None = None,
    min_duration: float | None = None,
) -> Relations:
    """The relations whose duration ``|t2 − t1|`` [s] lies in ``[min_duration,
    max_duration]`` (either bound optional), in their order. None left raises
    :class:`~slamkit.errors.InputError`."""
    d = np.abs(relations.t2 - relations.t1)
    keep = np.ones(d.size, dtype=bool)
    if max_duration is not None:
        keep &= d <= as_positive(max_duration, "max_duration")
    if min_duration is not None:
        keep &= d >= as_positive(min_duration, "min_duration", allow_zero=True)
    if not np.any(keep):
        raise InputError(
            f"relations: none of the {d.size} relations lasts between "
            f"{min_duration or 0:g} and {max_duration if max_duration is not None else 'inf'} s "
            f"(durations {float(d.min()):.3g}..{float(d.max()):.3g} s)"
        )
    return Relations(
        relations.t1[keep], relations.t2[keep], relations.deltas[keep], source=relations.source
    )


def _trajectory(times: ArrayLike, poses: ArrayLike) -> tuple[FloatArray, FloatArray]:
    T = as_array(times, "trajectory times", (None,))
    P = as_array(poses, "trajectory poses", (T.size, 3))
    if T.size == 0:
        raise InputError("trajectory: expected at least one pose, got none")
    steps = np.diff(T)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        raise InputError(
            f"trajectory times: expected strictly increasing stamps, got {T[k]!r} then "
            f"{T[k + 1]!r} at samples {k} and {k + 1}"
        )
    return T, P


def poses_at_stamps(
    times: ArrayLike,
    poses: ArrayLike,
    stamps: ArrayLike,
    *,
    max_gap: float = DEFAULT_MAX_GAP,
    stamp_tol: float = STAMP_TOLERANCE,
) -> tuple[FloatArray, BoolArray]:
    """Poses ``(m, 3)`` of a trajectory ``times (N,)`` (strictly increasing), ``poses (N, 3)``
    at ``stamps (m,)`` by the module's rule (a sample within ``stamp_tol``, else the
    interpolation between neighbours both within ``max_gap``), and the mask ``(m,)`` of the
    covered stamps. Rows of uncovered stamps are zero; read them through the mask."""
    T, P = _trajectory(times, poses)
    q = as_array(stamps, "stamps", (None,))
    gap = as_positive(max_gap, "max_gap", allow_zero=True)
    tol = as_positive(stamp_tol, "stamp_tol", allow_zero=True)
    out = np.zeros((q.size, 3))
    # Nearest sample: an exact (within tol) match takes its pose as recorded.
    hi = np.clip(np.searchsorted(T, q, side="left"), 0, T.size - 1)
    lo = np.clip(hi - 1, 0, T.size - 1)
    nearest = np.where(np.abs(T[lo] - q) <= np.abs(T[hi] - q), lo, hi)
    exact = np.abs(T[nearest] - q) <= tol
    out[exact] = P[nearest[exact]]
    # Otherwise a strict bracket T[lo] < q < T[hi] with both ends within max_gap of q.
    inside = (T[0] < q) & (q < T[-1])
    bracket = ~exact & inside & (q - T[lo] <= gap) & (T[hi] - q <= gap)
    if np.any(bracket):
        out[bracket] = interpolate_poses(T, P, q[bracket])
    return out, exact | bracket


def _std(values: FloatArray) -> float:
    return float(np.std(values, ddof=1)) if values.size > 1 else 0.0


def relation_errors(
    times: ArrayLike,
    poses: ArrayLike,
    relations: Relations,
    *,
    max_gap: float = DEFAULT_MAX_GAP,
    stamp_tol: float = STAMP_TOLERANCE,
    max_duration: float | None = None,
) -> RelationError:
    """The relation metric of a trajectory of world poses ``times (N,)`` [s] (strictly
    increasing), ``poses (N, 3)`` ``(x, y, θ)`` of the robot, against reference
    ``relations`` in the robot frame (see the module docstring for the error, the rule for
    the poses at the stamps, and the statistics).

    ``max_duration`` [s]: score only the relations with ``|t2 − t1|`` at most this (e.g. the
    short relations that odometry alone should get right); the coverage is then over those.
    A trajectory that covers no relation raises :class:`~slamkit.errors.InputError` naming
    both time spans."""
    T, P = _trajectory(times, poses)
    rel = relations
    if max_duration is not None:
        rel = select_relations(relations, max_duration=max_duration)
    x1, ok1 = poses_at_stamps(T, P, rel.t1, max_gap=max_gap, stamp_tol=stamp_tol)
    x2, ok2 = poses_at_stamps(T, P, rel.t2, max_gap=max_gap, stamp_tol=stamp_tol)
    covered = ok1 & ok2
    if not np.any(covered):
        stamps = rel.stamps
        raise InputError(
            f"relations: the trajectory ({T.size} poses, {T[0]:.6f}..{T[-1]:.6f} s) covers "
            f"no relation of {len(rel)} (stamps {stamps[0]:.6f}..{stamps[-1]:.6f} s) with "
            f"max_gap {float(max_gap):g} s"
        )
    estimated = between(x1[covered], x2[covered])  # δ̂ = x̂(t1)⁻¹ ⊕ x̂(t2)
    err = between(rel.deltas[covered], estimated)  # e = δ⁻¹ ⊕ δ̂ (between wraps e_θ)
    trans = np.hypot(err[:, 0], err[:, 1])
    rot = np.degrees(np.abs(err[:, 2]))
    return RelationError(
        t1=rel.t1[covered],
        t2=rel.t2[covered],
        errors=err,
        translation_errors=trans,
        rotation_errors_deg=rot,
        covered=covered,
        translation_mean=float(np.mean(trans)),
        translation_std=_std(trans),
        rotation_mean_deg=float(np.mean(rot)),
        rotation_std_deg=_std(rot),
        translation_sq_mean=float(np.mean(trans**2)),
        rotation_sq_mean_deg=float(np.mean(rot**2)),
        translation_max=float(np.max(trans)),
        rotation_max_deg=float(np.max(rot)),
        max_gap=float(max_gap),
        max_duration=None if max_duration is None else float(max_duration),
    )
