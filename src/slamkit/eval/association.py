"""How well an estimator associated readings with landmarks, against the true association.

An estimator that is given no landmark ids numbers its landmarks itself, so its ids cannot be
compared with the true ones directly. Each true landmark's *estimate* is taken to be the
estimated landmark that holds most of its readings; a reading is then correctly associated
when it updated (or started) exactly that one. This scores a map that splits one true
landmark into two (a duplicate: the smaller part's readings count as wrong) and one that
merges two true landmarks (the smaller one's readings count as wrong), without a separate
matching step.

An estimator that deletes features (EKF-SLAM's provisional features that were missed, a
landmark removed later) has numbered them and given them readings, but they are not in its
map. Given the ids of the final map (``kept``), the map's counts are over the map alone:
a spurious landmark is a landmark *of the map* that is no true landmark's estimate, and the
features that got readings but are not in the map are counted apart (``not_in_map``), so
``estimated_landmarks = in_map + not_in_map``.

``spurious_created`` counts over every feature instead, the deleted ones included: the
features started that are no true landmark's estimate (each true landmark's estimate chosen
among all features), so ``estimated_landmarks = (true landmarks with an estimate) +
spurious_created``. A true landmark whose provisional feature was deleted and started again
adds one to it each time, though the map holds none of them: Victoria Park's EKF-SLAM
started 972 features for 299 trees, 675 of them spurious creations, and ended with 331
landmarks, 49 of them spurious (``duplicates``): 641 features were deleted while
provisional.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit.errors import InputError, ShapeError

__all__ = ["AssociationScores", "association_scores"]


@dataclass(frozen=True)
class AssociationScores:
    """Association quality over the readings whose true landmark is known."""

    readings: int
    """Readings with a known true landmark (true id ``>= 0``)."""
    used: int
    """Of those, readings the estimator used (estimated id ``>= 0``)."""
    accuracy: float
    """Correct readings over all scored readings (an unused reading counts as wrong)."""
    precision: float
    """Correct readings over the used ones (nan when none were used)."""
    duplicates: int
    """Landmarks of the map (all estimated landmarks when the map's ids are not given) that
    are the estimate of no true landmark (a landmark mapped twice, a failed loop closure,
    clutter turned into a landmark)."""
    merged: int
    """Landmarks of the map that are the estimate of more than one true landmark."""
    true_landmarks: int
    estimated_landmarks: int
    """Estimated landmarks that got a reading, in the map or not."""
    in_map: int
    """Of those, the ones in the final map (all of them when its ids are not given)."""
    not_in_map: int
    """Of those, features deleted or still provisional at the end."""
    spurious_created: int = 0
    """Features started (with a reading) that are no true landmark's estimate, counted over
    every feature, deleted ones included: a landmark started again after its feature was
    deleted counts here once more, though it is not in the map."""

    def as_dict(self) -> dict[str, float | int]:
        return {
            "readings": self.readings,
            "used": self.used,
            "accuracy": self.accuracy,
            "precision": self.precision,
            "duplicates": self.duplicates,
            "merged": self.merged,
            "true_landmarks": self.true_landmarks,
            "estimated_landmarks": self.estimated_landmarks,
            "in_map": self.in_map,
            "not_in_map": self.not_in_map,
            "spurious_created": self.spurious_created,
        }


def _primaries(true: NDArray[np.int64], est: NDArray[np.int64]) -> tuple[NDArray[np.int64], ...]:
    """``(true ids, their estimate)``: for each true landmark among ``true`` the estimated
    landmark holding most of its readings (``est`` paired with ``true``, all used)."""
    pairs, counts = np.unique(np.stack([true, est]), axis=1, return_counts=True)
    order = np.lexsort((-counts, pairs[0]))  # by true id, then most readings first
    pairs = pairs[:, order]
    first = np.r_[True, pairs[0, 1:] != pairs[0, :-1]] if pairs.size else np.zeros(0, bool)
    return pairs[0, first], pairs[1, first]


def association_scores(
    estimated_ids: ArrayLike,
    true_ids: ArrayLike,
    *,
    same_ids: bool = False,
    kept: ArrayLike | None = None,
) -> AssociationScores:
    """Score the landmark ``estimated_ids (N,)`` an estimator gave each reading (``-1``:
    unused) against the ``true_ids (N,)`` of the same readings (``-1``: unknown, not
    scored). See the module docstring for the definitions. ``same_ids``: the estimator
    numbers landmarks as the truth does (localization in a known map), so a reading is
    correct only when it got exactly its true id — each true landmark's estimate is itself,
    not the estimated landmark holding most of its readings. ``kept``: the ids of the
    estimator's final map; ``duplicates`` and ``merged`` are then counted among them (each
    true landmark's estimate chosen among the map's landmarks), the other features apart."""
    est = np.asarray(estimated_ids)
    true = np.asarray(true_ids)
    if est.ndim != 1 or true.shape != est.shape:
        raise ShapeError(
            f"association_scores: expected two (N,) id arrays of one length, got shapes "
            f"{est.shape} and {true.shape}"
        )
    if not (np.issubdtype(est.dtype, np.integer) and np.issubdtype(true.dtype, np.integer)):
        raise InputError("association_scores: expected integer landmark ids")
    scored = true >= 0
    if not np.any(scored):
        raise InputError("association_scores: no reading has a known true landmark")
    est, true = est[scored].astype(np.int64), true[scored].astype(np.int64)
    used = est >= 0
    # primary[t] = the estimated landmark holding most readings of true landmark t
    primary_true, primary_est = _primaries(true[used], est[used])
    if same_ids:
        primary_true = primary_est = np.unique(true)
    expected = np.full(true.size, -2, dtype=np.int64)
    pos = np.searchsorted(primary_true, true)
    known = (pos < primary_true.size) & (primary_true[np.minimum(pos, primary_true.size - 1)]
                                         == true)  # fmt: skip
    expected[known] = primary_est[pos[known]]
    correct = used & (est == expected)
    estimated = np.unique(est[used])
    in_map = estimated
    map_primaries = primary_est
    if kept is not None:  # the map's counts over the map: its own primaries
        in_map = np.intersect1d(estimated, np.asarray(kept, dtype=np.int64))
        on_map = used & np.isin(est, in_map)
        map_primaries = _primaries(true[on_map], est[on_map])[1]
        if same_ids:
            map_primaries = np.intersect1d(np.unique(true), in_map)
    primaries, times = np.unique(map_primaries, return_counts=True)
    return AssociationScores(
        readings=int(true.size),
        used=int(used.sum()),
        accuracy=float(correct.mean()),
        precision=float(correct[used].mean()) if np.any(used) else float("nan"),
        duplicates=int(np.setdiff1d(in_map, primaries).size),
        merged=int(np.sum(times > 1)),
        true_landmarks=int(np.unique(true).size),
        estimated_landmarks=int(estimated.size),
        in_map=int(in_map.size),
        not_in_map=int(estimated.size - in_map.size),
        spurious_created=int(np.setdiff1d(estimated, primary_est).size),
    )
