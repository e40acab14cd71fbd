"""Accuracy of an estimated landmark map against the true one.

Landmarks are matched by id, or — for a SLAM map built without ids, whose landmarks carry
numbers of the estimator's own — by position (:func:`match_landmarks`). Because a SLAM map is
only defined up to the choice of world frame, the matched estimated positions are by default
first aligned onto the true ones with the least-squares rigid (optionally similarity)
transform; the remaining per-landmark distances are the map error.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from slamkit._validation import FloatArray
from slamkit.errors import ConfigError, GeometryError, InputError
from slamkit.eval.trajectory import error_summary
from slamkit.geometry.alignment import Similarity, align_points_2d
from slamkit.maps.types import LandmarkMap

__all__ = ["LandmarkError", "LandmarkMatch", "landmark_map_error", "match_landmarks"]


@dataclass(frozen=True, eq=False)
class LandmarkError:
    """Per-landmark position errors of the landmarks both maps share."""

    ids: NDArray[np.int64]
    """Ids present in both maps, increasing ``(K,)``."""
    errors: FloatArray
    """Distance ``‖aligned estimate − truth‖`` per matched landmark ``(K,)``, metres."""
    aligned_positions: FloatArray
    """Matched estimated positions after alignment ``(K, 2)``."""
    alignment: Similarity
    """Transform applied to the estimate (identity when ``align=False``)."""
    missing_ids: NDArray[np.int64]
    """True landmarks the estimate does not contain."""
    spurious_ids: NDArray[np.int64]
    """Estimated landmarks with no true counterpart."""
    rmse: float
    mean: float
    median: float
    max: float

    @property
    def n_matched(self) -> int:
        return int(self.ids.size)

    @property
    def n_missing(self) -> int:
        return int(self.missing_ids.size)

    @property
    def n_spurious(self) -> int:
        return int(self.spurious_ids.size)

    def as_dict(self) -> dict[str, float | int]:
        """The summary as plain Python values (JSON-ready); arrays are left out."""
        return {
            "n_matched": self.n_matched,
            "n_missing": self.n_missing,
            "n_spurious": self.n_spurious,
            "rmse": self.rmse,
            "mean": self.mean,
            "median": self.median,
            "max": self.max,
            "alignment_tx": float(self.alignment.translation[0]),
            "alignment_ty": float(self.alignment.translation[1]),
            "alignment_angle": self.alignment.angle,
            "alignment_scale": self.alignment.scale,
        }


def landmark_map_error(
    estimate: LandmarkMap,
    truth: LandmarkMap,
    align: bool = True,
    with_scale: bool = False,
    match: Literal["id", "position"] = "id",
    gate: float | None = None,
) -> LandmarkError:
    """Compare an estimated landmark map with the true one.

    ``match="id"`` pairs landmarks by id; ``match="position"`` pairs them one-to-one by
    position within ``gate`` metres (:func:`match_landmarks`; the reported ``ids`` are then
    the true ids, ``spurious_ids`` the unmatched estimated ones). With ``align`` the matched
    estimated positions are first mapped onto the true ones by the least-squares rotation and
    translation (plus scale with ``with_scale``); this needs at least two matched landmarks
    at distinct positions. Landmarks only in ``truth`` are reported as missing, those only in
    ``estimate`` as spurious; neither enters the error.
    """
    if not isinstance(estimate, LandmarkMap) or not isinstance(truth, LandmarkMap):
        raise InputError(
            f"landmark_map_error: expected two LandmarkMap values, got "
            f"{type(estimate).__name__} and {type(truth).__name__}"
        )
    if with_scale and not align:
        raise ConfigError("with_scale: only meaningful with align=True")
    if match == "position":
        m = match_landmarks(estimate.positions, truth.positions, gate=gate, align=align)
        i_est, i_true = m.estimate_index, m.truth_index
        ids = truth.ids[i_true]
        order = np.argsort(ids)
        ids, i_est, i_true = ids[order], i_est[order], i_true[order]
        spurious = np.delete(estimate.ids, i_est)
    elif match == "id":
        ids, i_est, i_true = np.intersect1d(estimate.ids, truth.ids, return_indices=True)
        spurious = np.setdiff1d(estimate.ids, truth.ids)
    else:
        raise ConfigError(f"match: expected 'id' or 'position', got {match!r}")
    if ids.size == 0:
        raise InputError(
            "landmark_map_error: the two maps share no landmark id"
            if match == "id"
            else "landmark_map_error: no estimated landmark lies within the gate of a true one"
        )
    p_est = estimate.positions[i_est]
    p_true = truth.positions[i_true]
    if align:
        alignment = align_points_2d(p_est, p_true, with_scale=with_scale)
    else:
        alignment = Similarity.identity(2)
    aligned = alignment.apply_to_points(p_est)
    d = p_true - aligned
    errors = np.hypot(d[:, 0], d[:, 1])
    s = error_summary(errors)
    return LandmarkError(
        ids=ids.astype(np.int64),
        errors=errors,
        aligned_positions=aligned,
        alignment=alignment,
        missing_ids=np.setdiff1d(truth.ids, ids).astype(np.int64),
        spurious_ids=np.sort(spurious).astype(np.int64),
        rmse=s.rmse,
        mean=s.mean,
        median=s.median,
        max=s.max,
    )


@dataclass(frozen=True, eq=False)
class LandmarkMatch:
    """A one-to-one pairing of estimated with true landmark positions."""

    estimate_index: NDArray[np.int64]
    """Rows of the estimated positions that have a partner ``(K,)``."""
    truth_index: NDArray[np.int64]
    """Their partners' rows in the true positions ``(K,)``."""
    alignment: Similarity
    """The rigid transform (estimate → truth) under which they were paired."""
    gate: float
    """Largest distance [m] allowed between partners after alignment."""


_MAX_ANCHORS = 12  # estimated landmarks whose pairs propose alignments
_MAX_HYPOTHESES = 20_000


def match_landmarks(
    estimate: FloatArray,
    truth: FloatArray,
    *,
    gate: float | None = None,
    align: bool = True,
    iterations: int = 5,
) -> LandmarkMatch:
    """Pair estimated landmark positions ``(K, 2)`` with true ones ``(M, 2)`` one-to-one,
    each pair within ``gate`` metres, when ids cannot say which is which.

    ``gate`` defaults to half the median distance from a true landmark to its nearest true
    neighbour: beyond that a pairing is ambiguous. Without ``align`` the two maps are taken
    to share a frame and paired directly (optimal assignment, :func:`~scipy.optimize.
    linear_sum_assignment`, on distances within the gate). With ``align`` the frame is found
    first: the identity and, if it explains too few landmarks, every rigid transform that
    maps a pair of *anchor* estimated landmarks (up to 12, spread over the map) onto a pair
    of true landmarks at the same distance (within the gate) is scored by the number of
    estimated landmarks it brings within the gate of a true one; the best is refined by
    alternating assignment and least-squares alignment of the pairs. Deterministic.
    """
    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 2)
    ref = np.asarray(truth, dtype=np.float64).reshape(-1, 2)
    if est.shape[0] == 0 or ref.shape[0] == 0:
        raise InputError("match_landmarks: expected landmarks in both maps")
    if not (np.all(np.isfinite(est)) and np.all(np.isfinite(ref))):
        raise InputError("match_landmarks: expected finite positions")
    tree = cKDTree(ref)
    if gate is None:
        if ref.shape[0] < 2:
            raise InputError("match_landmarks: a gate is needed when the truth has one landmark")
        nn = tree.query(ref, k=2)[0][:, 1]
        gate = 0.5 * float(np.median(nn))
    if not (np.isfinite(gate) and gate > 0):
        raise ConfigError(f"gate: expected a distance > 0, got {gate}")
    pose = np.zeros(3)
    if align:
        pose = _best_alignment(est, ref, tree, gate)
    alignment = Similarity.from_pose(pose)
    i_est = i_ref = np.zeros(0, dtype=np.int64)
    for _ in range(max(1, iterations)):
        i_est, i_ref = _assign(alignment.apply_to_points(est), ref, gate)
        if not align or i_est.size < 2:
            break
        try:
            refined = align_points_2d(est[i_est], ref[i_ref])
        except GeometryError:
            break
        alignment = refined
    if align and i_est.size >= 2:  # the final pairs under the final alignment
        i_est, i_ref = _assign(alignment.apply_to_points(est), ref, gate)
    return LandmarkMatch(i_est, i_ref, alignment, float(gate))


def _assign(
    est: FloatArray, ref: FloatArray, gate: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Optimal one-to-one assignment on distances, pairs farther than ``gate`` dropped."""
    d = np.linalg.norm(est[:, None, :] - ref[None, :, :], axis=2)
    cost = np.where(d <= gate, d, 1e6 * (1.0 + gate))
    r, c = linear_sum_assignment(cost)
    ok = d[r, c] <= gate
    return r[ok].astype(np.int64), c[ok].astype(np.int64)


def _inliers(est: FloatArray, poses: FloatArray, tree: cKDTree, gate: float) -> FloatArray:
    """Estimated landmarks within ``gate`` of a true one under each pose ``(H, 3)``."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    x = c[:, None] * est[:, 0] - s[:, None] * est[:, 1] + poses[:, 0:1]
    y = s[:, None] * est[:, 0] + c[:, None] * est[:, 1] + poses[:, 1:2]
    d = tree.query(np.stack([x.ravel(), y.ravel()], axis=1), distance_upper_bound=gate)[0]
    counts: FloatArray = np.isfinite(d).reshape(poses.shape[0], -1).sum(axis=1).astype(float)
    return counts


def _best_alignment(est: FloatArray, ref: FloatArray, tree: cKDTree, gate: float) -> FloatArray:
    """The pose ``(x, y, θ)`` of the truth frame's transform of the estimate with the most
    inliers (see :func:`match_landmarks`)."""
    identity = np.zeros((1, 3))
    best = float(_inliers(est, identity, tree, gate)[0])
    if best >= 0.8 * min(est.shape[0], ref.shape[0]) or est.shape[0] < 2 or ref.shape[0] < 2:
        return identity[0]
    # anchors: spread over the map (farthest-point order from the first landmark)
    anchors = [0]
    dist = np.linalg.norm(est - est[0], axis=1)
    while len(anchors) < min(_MAX_ANCHORS, est.shape[0]):
        nxt = int(np.argmax(dist))
        anchors.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(est - est[nxt], axis=1))
    ia, ja = np.triu_indices(len(anchors), 1)
    ea, eb = est[np.asarray(anchors)[ia]], est[np.asarray(anchors)[ja]]
    it, jt = np.triu_indices(ref.shape[0], 1)
    it, jt = np.concatenate([it, jt]), np.concatenate([jt, it])  # both orders of each pair
    d_true = np.linalg.norm(ref[jt] - ref[it], axis=1)
    order = np.argsort(d_true)
    d_sorted = d_true[order]
    hyp_e, hyp_t = [], []
    for k, d in enumerate(np.linalg.norm(eb - ea, axis=1)):
        lo, hi = np.searchsorted(d_sorted, [d - gate, d + gate])
        hyp_t.append(order[lo:hi])
        hyp_e.append(np.full(hi - lo, k))
    e_idx, t_idx = np.concatenate(hyp_e), np.concatenate(hyp_t)
    if e_idx.size > _MAX_HYPOTHESES:  # keep an even spread of them
        keep = np.linspace(0, e_idx.size - 1, _MAX_HYPOTHESES).astype(np.int64)
        e_idx, t_idx = e_idx[keep], t_idx[keep]
    if e_idx.size == 0:
        return identity[0]
    # the rigid transform taking the anchor pair onto the true pair
    src_a, src_b = ea[e_idx], eb[e_idx]
    dst_a, dst_b = ref[it[t_idx]], ref[jt[t_idx]]
    theta = np.arctan2(*(dst_b - dst_a)[:, ::-1].T) - np.arctan2(*(src_b - src_a)[:, ::-1].T)
    c, s = np.cos(theta), np.sin(theta)
    mid_s, mid_d = 0.5 * (src_a + src_b), 0.5 * (dst_a + dst_b)
    tx = mid_d[:, 0] - (c * mid_s[:, 0] - s * mid_s[:, 1])
    ty = mid_d[:, 1] - (s * mid_s[:, 0] + c * mid_s[:, 1])
    poses = np.stack([tx, ty, theta], axis=1)
    counts = np.concatenate(
        [_inliers(est, poses[i : i + 2000], tree, gate) for i in range(0, poses.shape[0], 2000)]
    )
    k = int(np.argmax(counts))
    return poses[k] if counts[k] > best else identity[0]
