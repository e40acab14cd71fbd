"""Absolute and relative pose error between two trajectory files, by the rules evo uses.

This is what ``slamkit eval ape`` / ``slamkit eval rpe`` compute, on SE(3) poses
``(N, 4, 4)`` (planar trajectories are SE(3) poses with z = 0), so that the numbers equal
those of evo's ``evo_ape`` / ``evo_rpe`` on the same files (a test checks 1e-6):

* **association** (:func:`associate_stamps`): the trajectory with fewer poses is walked in
  order; each of its stamps is paired with the nearest stamp of the other (after adding
  ``offset`` to the estimate's stamps), if within ``max_diff`` seconds; on a tie the earlier
  stamp wins. Poses of either trajectory may be used at most once from the shorter side,
  more than once from the longer (as evo).
* **alignment** (:func:`align_estimate`): none by default, as evo; or Umeyama's
  least-squares fit of the estimated positions onto the reference ones — ``"se3"`` (rotation
  + translation: evo's ``-a``), ``"sim3"`` (and scale: ``-as``), ``"scale"`` (the scale of
  the Sim(3) fit alone, applied to the translations: ``-s``), ``"se2"`` (rotation about z and
  translation in x, y only, for planar robots; no evo flag); optionally from the first
  ``n_align`` pairs only. The estimate ``P_i`` becomes ``S P_i`` with ``S = [sR t; 0 1]``
  applied as a scaling of the translations by ``s`` followed by the rigid motion (evo's
  order).
* **APE** (:func:`absolute_pose_error`): translation ``‖t(P_i) − t(Q_i)‖`` and rotation
  angle ``∠(Q_i⁻¹ P_i)`` per pair.
* **RPE** (:func:`relative_pose_error_se3`): for index pairs ``(i, j)`` ``Δ`` apart — in
  frames (``j = i + Δ``, consecutive ``i = 0, Δ, 2Δ, …`` or all) or in metres of path
  (:func:`path_pairs`, on the estimate's positions as evo does by default) —
  ``E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)``, its translation norm and rotation angle.

Statistics (:class:`ErrorStatistics`) are those evo prints: rmse, mean, median, std
(population), min, max, sse. Arrays in, result records out; nothing here reads files or plots.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.errors import ConfigError, InputError, ShapeError
from slamkit.geometry.alignment import Similarity, align_points

__all__ = [
    "ALIGNMENTS",
    "Alignment",
    "DeltaUnit",
    "ErrorStatistics",
    "PoseErrorResult",
    "absolute_pose_error",
    "align_estimate",
    "alignment_from_evo_flags",
    "associate_stamps",
    "compare_trajectories",
    "describe_alignment",
    "path_pairs",
    "relative_pose_error_se3",
    "rotation_angles",
]

Alignment = Literal["none", "se3", "sim3", "scale", "se2"]
DeltaUnit = Literal["frames", "m"]
ALIGNMENTS: tuple[str, ...] = ("none", "se3", "sim3", "scale", "se2")
"""The alignments, evo's first: none (no flag), se3 (``-a``), sim3 (``-as``), scale
(``-s``); then se2, slamkit's planar one."""

_ALIGNMENT_WORDS = {
    "none": "not aligned",
    "se3": "SE(3) Umeyama alignment",
    "sim3": "Sim(3) Umeyama alignment",
    "scale": "scale corrected",
    "se2": "SE(2) Umeyama alignment in x-y",
}


def alignment_from_evo_flags(align: bool, correct_scale: bool) -> Alignment:
    """The alignment evo's ``-a`` (``align``) and ``-s`` (``correct_scale``) ask for:
    neither ``"none"``, ``-a`` ``"se3"``, ``-s`` ``"scale"``, both (``-as``) ``"sim3"``."""
    if align:
        return "sim3" if correct_scale else "se3"
    return "scale" if correct_scale else "none"


def describe_alignment(alignment: str) -> str:
    """The alignment in words, as titles and console lines say it ("not aligned",
    "Sim(3) Umeyama alignment", ...)."""
    if alignment not in _ALIGNMENT_WORDS:
        raise ConfigError(f"alignment: expected one of {', '.join(ALIGNMENTS)}, got {alignment!r}")
    return _ALIGNMENT_WORDS[alignment]


IndexArray = NDArray[np.int64]


@dataclass(frozen=True)
class ErrorStatistics:
    """Summary of per-pair errors, as evo reports them (std is the population std)."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    sse: float
    count: int

    @classmethod
    def of(cls, errors: ArrayLike) -> ErrorStatistics:
        e = np.asarray(errors, dtype=float)
        if e.size == 0:
            raise InputError("error statistics: no errors (no pose pairs to compare)")
        sq = e * e
        return cls(
            rmse=float(np.sqrt(np.mean(sq))),
            mean=float(np.mean(e)),
            median=float(np.median(e)),
            std=float(np.std(e)),
            min=float(np.min(e)),
            max=float(np.max(e)),
            sse=float(np.sum(sq)),
            count=int(e.size),
        )

    def as_dict(self) -> dict[str, float | int]:
        return {
            "rmse": self.rmse,
            "mean": self.mean,
            "median": self.median,
            "std": self.std,
            "min": self.min,
            "max": self.max,
            "sse": self.sse,
            "count": self.count,
        }


def _poses(poses: ArrayLike, name: str) -> FloatArray:
    p = as_array(poses, name, (None, 4, 4))
    if not np.allclose(p[:, 3, :], [0.0, 0.0, 0.0, 1.0]):
        raise ShapeError(f"{name}: expected homogeneous poses (last row 0 0 0 1)")
    return p


def associate_stamps(
    times_ref: ArrayLike, times_est: ArrayLike, *, max_diff: float = 0.01, offset: float = 0.0
) -> tuple[IndexArray, IndexArray]:
    """Index pairs ``(idx_ref, idx_est)`` of stamps within ``max_diff`` seconds, the estimate's
    stamps shifted by ``offset`` (see the module docstring for the rule). Raises
    :class:`~slamkit.errors.InputError` when no stamps match."""
    t_ref = as_array(times_ref, "reference times", (None,))
    t_est = as_array(times_est, "estimate times", (None,))
    if not (np.isfinite(max_diff) and max_diff >= 0):
        raise ConfigError(f"max_diff: expected a finite number >= 0, got {max_diff!r}")
    if not np.isfinite(offset):
        raise ConfigError(f"offset: expected a finite number, got {offset!r}")
    est_longer = t_est.size > t_ref.size
    short, long_ = (t_ref, t_est) if est_longer else (t_est, t_ref)
    long_ = long_ + (offset if est_longer else -offset)
    idx_short, idx_long = _nearest(short, long_, float(max_diff))
    if idx_short.size == 0:
        raise InputError(
            f"no matching time stamps between the reference and the estimate with max. "
            f"difference {max_diff} s and offset {offset} s"
        )
    return (idx_short, idx_long) if est_longer else (idx_long, idx_short)


def _nearest(
    short: FloatArray, long_: FloatArray, max_diff: float
) -> tuple[IndexArray, IndexArray]:
    if long_.size == 0 or short.size == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty.copy()
    if np.any(np.diff(long_) < 0):  # unsorted: the first nearest stamp, by a full search
        best = np.fromiter(
            (np.argmin(np.abs(long_ - t)) for t in short), dtype=np.int64, count=short.size
        )  # one row at a time: O(M) memory, not an (N, M) matrix
        keep = np.abs(long_[best] - short) <= max_diff
        return np.flatnonzero(keep).astype(np.int64), best[keep]
    inside = (short >= long_[0] - max_diff) & (short <= long_[-1] + max_diff)
    upper = np.minimum(np.searchsorted(long_, short, side="right"), long_.size - 1)
    diff_ub = long_[upper] - short
    diff_lb = np.where(upper > 0, short - long_[np.maximum(upper - 1, 0)], np.inf)
    take_ub = (diff_ub <= max_diff) & (diff_ub < diff_lb)
    take_lb = ~take_ub & (diff_lb <= max_diff) & (diff_lb <= diff_ub)
    keep = inside & (take_ub | take_lb)
    best = np.where(take_ub, upper, upper - 1)
    return np.flatnonzero(keep).astype(np.int64), best[keep].astype(np.int64)


def align_estimate(
    reference: ArrayLike, estimate: ArrayLike, alignment: Alignment, n_align: int | None = None
) -> tuple[FloatArray, Similarity | None]:
    """The estimate ``(N, 4, 4)`` aligned onto the paired reference ``(N, 4, 4)`` and the
    similarity used (``None`` for ``"none"``; for ``"scale"`` the identity motion with the
    Sim(3) fit's scale); ``n_align``: fit to the first pairs only."""
    ref = _poses(reference, "reference poses")
    est = _poses(estimate, "estimated poses")
    if ref.shape != est.shape:
        raise ShapeError(f"estimated poses: expected the reference's {ref.shape}, got {est.shape}")
    if alignment not in ALIGNMENTS:
        raise ConfigError(f"alignment: expected one of {', '.join(ALIGNMENTS)}, got {alignment!r}")
    if alignment == "none":
        return est.copy(), None
    n = ref.shape[0] if n_align is None else int(n_align)
    if not 1 <= n <= ref.shape[0]:
        raise ConfigError(f"n_align: expected 1..{ref.shape[0]} pairs, got {n_align!r}")
    dims = 2 if alignment == "se2" else 3
    fit = align_points(
        est[:n, :dims, 3], ref[:n, :dims, 3], with_scale=alignment in ("sim3", "scale")
    )
    if alignment == "scale":  # evo's -s: the scale of the Sim(3) fit, no motion
        fit = Similarity(np.eye(3), np.zeros(3), fit.scale)
    rot = np.eye(4)
    rot[:dims, :dims] = fit.rotation
    rot[:dims, 3] = fit.translation
    out = est.copy()
    out[:, :3, 3] *= fit.scale  # evo: scale the translations, then the rigid motion
    return np.einsum("ij,njk->nik", rot, out), fit


def rotation_angles(rotations: ArrayLike) -> FloatArray:
    """The rotation angle ``(N,)`` [rad] of each rotation matrix ``(N, 3, 3)``, from the
    axis and cosine parts together (``atan2``): exact near 0, where ``arccos`` of the trace
    loses half the digits."""
    r = np.asarray(rotations, dtype=float)
    axis = np.stack(
        [r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], axis=-1
    )
    sin = 0.5 * np.linalg.norm(axis, axis=-1)
    cos = 0.5 * (np.trace(r, axis1=1, axis2=2) - 1.0)
    return np.arctan2(sin, cos)


def _inverse(poses: FloatArray) -> FloatArray:
    """Inverses of rigid poses; for a scaled estimate (Sim(3)-aligned translations) the
    rotation block is still orthonormal, so this is exact."""
    out = np.zeros_like(poses)
    rt = np.transpose(poses[:, :3, :3], (0, 2, 1))
    out[:, :3, :3] = rt
    out[:, :3, 3] = -np.einsum("nij,nj->ni", rt, poses[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def absolute_pose_error(reference: ArrayLike, estimate: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Per pair: translation error ``‖t(P_i) − t(Q_i)‖`` [m] and rotation error
    ``∠(Q_i⁻¹ P_i)`` [rad] of paired, aligned poses ``(N, 4, 4)``."""
    ref = _poses(reference, "reference poses")
    est = _poses(estimate, "estimated poses")
    trans = np.linalg.norm(est[:, :3, 3] - ref[:, :3, 3], axis=1)
    rel = np.einsum("nij,njk->nik", np.transpose(ref[:, :3, :3], (0, 2, 1)), est[:, :3, :3])
    return trans, rotation_angles(rel)


def path_pairs(positions: ArrayLike, delta: float, *, all_pairs: bool = False,
               tol: float = 0.0) -> IndexArray:  # fmt: skip
    """Index pairs ``(K, 2)`` about ``delta`` metres of travelled path apart (evo's rule):
    consecutive — a pair closes each time the path since the last one reaches ``delta`` —
    or all — from every pose, the later pose whose path distance is nearest ``delta``, kept
    when within ``tol``."""
    p = as_array(positions, "positions", (None, 3))
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    pairs: list[tuple[int, int]] = []
    if all_pairs:
        dist = np.concatenate([[0.0], np.cumsum(steps)])
        for i in range(dist.size - 1):
            ahead = np.abs(dist[i + 1 :] - dist[i] - delta)
            k = int(np.argmin(ahead))
            if ahead[k] <= tol:
                pairs.append((i, i + 1 + k))
    else:
        ids, path = [0], 0.0
        for k, step in enumerate(steps.tolist(), start=1):
            path += step
            if path >= delta:
                ids.append(k)
                path = 0.0
        pairs = list(itertools.pairwise(ids))
    return np.asarray(pairs, dtype=np.int64).reshape(-1, 2)


def relative_pose_error_se3(
    reference: ArrayLike,
    estimate: ArrayLike,
    *,
    delta: float = 1,
    all_pairs: bool = False,
    delta_unit: DeltaUnit = "frames",
    pairs_from_reference: bool = False,
    rel_tol: float = 0.1,
) -> tuple[IndexArray, FloatArray, FloatArray]:
    """Index pairs ``(K, 2)`` ``Δ = delta`` apart — frames, or metres of path
    (:func:`path_pairs` on the estimate's positions, or the reference's with
    ``pairs_from_reference``; all-pairs tolerance ``rel_tol · delta``, evo's defaults) — and,
    per pair, the translation [m] and rotation [rad] of ``E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)``."""
    ref = _poses(reference, "reference poses")
    est = _poses(estimate, "estimated poses")
    n = ref.shape[0]
    if delta_unit == "frames":
        if isinstance(delta, bool) or not float(delta).is_integer() or delta < 1:
            raise ConfigError(f"delta: expected an integer >= 1 frames, got {delta!r}")
        step = int(delta)
        first = np.arange(n - step) if all_pairs else np.arange(0, n, step)[:-1]
        pairs = np.column_stack([first, first + step]).astype(np.int64)
    elif delta_unit == "m":
        if not (np.isfinite(delta) and delta > 0):
            raise ConfigError(f"delta: expected a distance > 0 m, got {delta!r}")
        source = ref if pairs_from_reference else est
        pairs = path_pairs(source[:, :3, 3], float(delta), all_pairs=all_pairs,
                           tol=rel_tol * float(delta))  # fmt: skip
    else:
        raise ConfigError(f"delta_unit: expected 'frames' or 'm', got {delta_unit!r}")
    if pairs.shape[0] == 0:
        raise InputError(
            f"relative pose error: {n} poses hold no pair {delta:g} {delta_unit} apart"
        )
    i, j = pairs[:, 0], pairs[:, 1]
    q_rel = np.einsum("nij,njk->nik", _inverse(ref[i]), ref[j])
    p_rel = np.einsum("nij,njk->nik", _inverse(est[i]), est[j])
    e = np.einsum("nij,njk->nik", _inverse(q_rel), p_rel)
    return pairs, np.linalg.norm(e[:, :3, 3], axis=1), rotation_angles(e[:, :3, :3])


@dataclass(frozen=True)
class PoseErrorResult:
    """APE and RPE of an estimate against a reference, after association and alignment.

    ``times`` are the reference stamps of the pairs (``None`` for files without stamps);
    ``reference``/``estimate`` the paired poses, the estimate aligned."""

    alignment: Alignment
    similarity: Similarity | None
    times: FloatArray | None
    reference: FloatArray
    estimate: FloatArray
    ape_translation: FloatArray
    ape_rotation: FloatArray
    rpe_pairs: IndexArray
    rpe_translation: FloatArray
    rpe_rotation: FloatArray
    delta: float
    delta_unit: DeltaUnit
    all_pairs: bool
    matched: int
    reference_poses: int
    estimate_poses: int

    @property
    def ape(self) -> ErrorStatistics:
        """APE, translation part [m]."""
        return ErrorStatistics.of(self.ape_translation)

    @property
    def ape_rotation_deg(self) -> ErrorStatistics:
        return ErrorStatistics.of(np.degrees(self.ape_rotation))

    @property
    def rpe(self) -> ErrorStatistics:
        """RPE, translation part [m] per ``delta`` (frames or metres)."""
        return ErrorStatistics.of(self.rpe_translation)

    @property
    def rpe_rotation_deg(self) -> ErrorStatistics:
        return ErrorStatistics.of(np.degrees(self.rpe_rotation))

    def as_dict(self) -> dict[str, object]:
        sim = self.similarity
        return {
            "alignment": self.alignment,
            "alignment_scale": None if sim is None else sim.scale,
            "alignment_rotation": None if sim is None else sim.rotation.tolist(),
            "alignment_translation": None if sim is None else sim.translation.tolist(),
            "matched": self.matched,
            "reference_poses": self.reference_poses,
            "estimate_poses": self.estimate_poses,
            "ape_translation_m": self.ape.as_dict(),
            "ape_rotation_deg": self.ape_rotation_deg.as_dict(),
            "rpe_delta": self.delta,
            "rpe_delta_unit": self.delta_unit,
            "rpe_all_pairs": self.all_pairs,
            "rpe_translation_m": self.rpe.as_dict(),
            "rpe_rotation_deg": self.rpe_rotation_deg.as_dict(),
        }


def compare_trajectories(
    reference: ArrayLike,
    estimate: ArrayLike,
    *,
    times_ref: ArrayLike | None = None,
    times_est: ArrayLike | None = None,
    alignment: Alignment = "none",
    n_align: int | None = None,
    max_diff: float = 0.01,
    offset: float = 0.0,
    delta: float = 1,
    all_pairs: bool = False,
    delta_unit: DeltaUnit = "frames",
    pairs_from_reference: bool = False,
) -> PoseErrorResult:
    """Associate (by stamps when both have them, else by index: same length needed), align
    (not unless asked, as evo), and compute APE and RPE (see the module docstring)."""
    ref = _poses(reference, "reference poses")
    est = _poses(estimate, "estimated poses")
    if (times_ref is None) != (times_est is None):
        raise InputError("time stamps: give them for both trajectories or for neither")
    times = None
    if times_ref is not None and times_est is not None:
        t_ref = as_array(times_ref, "reference times", (ref.shape[0],))
        as_array(times_est, "estimate times", (est.shape[0],))
        i_ref, i_est = associate_stamps(t_ref, times_est, max_diff=max_diff, offset=offset)
        times = t_ref[i_ref]
    else:
        if ref.shape[0] != est.shape[0]:
            raise ShapeError(
                f"trajectories without time stamps are paired by index: expected the same "
                f"number of poses, got {ref.shape[0]} (reference) and {est.shape[0]} (estimate)"
            )
        i_ref = i_est = np.arange(ref.shape[0], dtype=np.int64)
    paired_ref = ref[i_ref]
    aligned, sim = align_estimate(paired_ref, est[i_est], alignment, n_align)
    ape_t, ape_r = absolute_pose_error(paired_ref, aligned)
    pairs, rpe_t, rpe_r = relative_pose_error_se3(
        paired_ref, aligned, delta=delta, all_pairs=all_pairs, delta_unit=delta_unit,
        pairs_from_reference=pairs_from_reference,
    )  # fmt: skip
    return PoseErrorResult(
        alignment=alignment,
        similarity=sim,
        times=times,
        reference=paired_ref,
        estimate=aligned,
        ape_translation=ape_t,
        ape_rotation=ape_r,
        rpe_pairs=pairs,
        rpe_translation=rpe_t,
        rpe_rotation=rpe_r,
        delta=float(delta),
        delta_unit=delta_unit,
        all_pairs=bool(all_pairs),
        matched=int(i_ref.size),
        reference_poses=int(ref.shape[0]),
        estimate_poses=int(est.shape[0]),
    )
