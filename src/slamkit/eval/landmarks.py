"""Accuracy of an estimated landmark map against the true one.

Landmarks are matched by id. Because a SLAM map is only defined up to the choice of world
frame, the matched estimated positions are by default first aligned onto the true ones with
the least-squares rigid (optionally similarity) transform; the remaining per-landmark
distances are the map error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.errors import ConfigError, InputError
from slamkit.eval.trajectory import _summary
from slamkit.geometry.alignment import Similarity, align_points_2d
from slamkit.maps.types import LandmarkMap

__all__ = ["LandmarkError", "landmark_map_error"]


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
) -> LandmarkError:
    """Compare an estimated landmark map with the true one, matching landmarks by id.

    With ``align`` the matched estimated positions are first mapped onto the true ones by the
    least-squares rotation and translation (plus scale with ``with_scale``); this needs at
    least two matched landmarks at distinct positions. Landmarks only in ``truth`` are
    reported as missing, those only in ``estimate`` as spurious; neither enters the error.
    """
    if not isinstance(estimate, LandmarkMap) or not isinstance(truth, LandmarkMap):
        raise InputError(
            f"landmark_map_error: expected two LandmarkMap values, got "
            f"{type(estimate).__name__} and {type(truth).__name__}"
        )
    if with_scale and not align:
        raise ConfigError("with_scale: only meaningful with align=True")
    ids, i_est, i_true = np.intersect1d(estimate.ids, truth.ids, return_indices=True)
    if ids.size == 0:
        raise InputError("landmark_map_error: the two maps share no landmark id")
    p_est = estimate.positions[i_est]
    p_true = truth.positions[i_true]
    if align:
        alignment = align_points_2d(p_est, p_true, with_scale=with_scale)
    else:
        alignment = Similarity.identity(2)
    aligned = alignment.apply_to_points(p_est)
    d = p_true - aligned
    errors = np.hypot(d[:, 0], d[:, 1])
    s = _summary(errors)
    return LandmarkError(
        ids=ids.astype(np.int64),
        errors=errors,
        aligned_positions=aligned,
        alignment=alignment,
        missing_ids=np.setdiff1d(truth.ids, estimate.ids).astype(np.int64),
        spurious_ids=np.setdiff1d(estimate.ids, truth.ids).astype(np.int64),
        rmse=s.rmse,
        mean=s.mean,
        median=s.median,
        max=s.max,
    )
