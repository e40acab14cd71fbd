"""One scan of landmark readings through EKF mapping: readings with ids update or start
their landmark, readings without are associated by nearest neighbour, readings too close to
the sensor are skipped; :class:`ReadingsOutcome` says what happened to each."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray
from slamkit.errors import InputError
from slamkit.estimation.readings import ReadingStatus
from slamkit.mapping.ekf_mapping.association import NEW, associate_nearest_unchecked
from slamkit.mapping.ekf_mapping.beliefs import LandmarkBelief
from slamkit.mapping.ekf_mapping.inputs import (
    as_landmark_ids,
    check_reading_inputs,
    require_invertible,
)
from slamkit.mapping.ekf_mapping.kernels import (
    association_distances_unchecked,
    initialise_unchecked,
    update_unchecked,
)
from slamkit.models.measurement import InvertibleLandmarkModel

__all__ = [
    "DISCARDED",
    "INITIALISED",
    "TOO_CLOSE",
    "UPDATED",
    "ReadingsOutcome",
    "process_readings",
    "process_readings_unchecked",
]

# The codes as module constants (the values of the enum in slamkit.estimation.readings).
UPDATED = ReadingStatus.UPDATED
INITIALISED = ReadingStatus.INITIALISED
DISCARDED = ReadingStatus.DISCARDED
TOO_CLOSE = ReadingStatus.TOO_CLOSE


@dataclass(frozen=True)
class ReadingsOutcome:
    """What happened to each reading of a scan ``(K,)``: the id of the landmark it updated or
    started (``-1`` if not used), a status code (:data:`UPDATED` = 0, :data:`INITIALISED` = 1,
    :data:`DISCARDED` = 2, :data:`TOO_CLOSE` = 3) and its NIS (NaN unless it updated a
    landmark)."""

    landmark_ids: NDArray[np.int64]
    status: NDArray[np.int64]
    nis: FloatArray

    @property
    def updated(self) -> NDArray[np.bool_]:
        return np.asarray(self.status == UPDATED)


def process_readings_unchecked(
    belief: LandmarkBelief,
    x: FloatArray,
    z: FloatArray,
    rid: NDArray[np.int64],
    R: FloatArray,
    model: InvertibleLandmarkModel,
    gate: float,
    new_gate: float,
    min_range: float,
) -> tuple[LandmarkBelief, ReadingsOutcome]:
    """:func:`process_readings` of checked arguments (the estimators' hot path)."""
    k = z.shape[0]
    out_ids = np.full(k, -1, dtype=np.int64)
    status = np.full(k, DISCARDED, dtype=np.int64)
    nis = np.full(k, np.nan)
    usable = np.ones(k, dtype=bool)
    if min_range > 0 and k:
        # Distance of the landmark each reading places, |g(x, z) − t|, for any model.
        d = np.hypot(*(model.inverse(x, z) - x[:2]).T)
        usable = d >= min_range
        status[~usable] = TOO_CLOSE

    known = np.flatnonzero((rid >= 0) & usable)
    # Rounds of distinct ids: round r takes the r-th reading of each id in this scan.
    while known.size:
        _, first = np.unique(rid[known], return_index=True)
        if first.size == known.size:  # the usual case: every id once
            now, known = known, known[:0]
        else:
            take = np.zeros(known.size, dtype=bool)
            take[first] = True
            now, known = known[take], known[~take]
        rows = belief.index_of(rid[now])
        fresh = now[rows < 0]
        if fresh.size:
            belief = initialise_unchecked(belief, x, z[fresh], rid[fresh], R, model)
            out_ids[fresh], status[fresh] = rid[fresh], INITIALISED
        old = now[rows >= 0]
        if old.size:
            belief, nis[old] = update_unchecked(belief, rows[rows >= 0], x, z[old], R, model)
            out_ids[old], status[old] = rid[old], UPDATED

    unknown = np.flatnonzero((rid < 0) & usable)
    if unknown.size:
        d = association_distances_unchecked(belief, x, z[unknown], R, model)
        match = associate_nearest_unchecked(d, gate, new_gate)
        hit = unknown[match >= 0]
        if hit.size:
            rows = match[match >= 0]
            belief, nis[hit] = update_unchecked(belief, rows, x, z[hit], R, model)
            out_ids[hit], status[hit] = belief.ids[rows], UPDATED
        new = unknown[match == NEW]
        if new.size:
            start = int(belief.ids.max()) + 1 if len(belief) else 0
            new_ids = np.arange(start, start + new.size, dtype=np.int64)
            belief = initialise_unchecked(belief, x, z[new], new_ids, R, model)
            out_ids[new], status[new] = new_ids, INITIALISED
    return belief, ReadingsOutcome(out_ids, status, nis)


def process_readings(
    belief: LandmarkBelief,
    pose: ArrayLike,
    z: ArrayLike,
    ids: ArrayLike,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
    *,
    gate: float,
    new_gate: float,
    min_range: float = 0.0,
) -> tuple[LandmarkBelief, ReadingsOutcome]:
    """One scan: readings ``z (K, m)`` with ``ids (K,)`` (``-1`` = unknown) from ``pose``.

    Readings that place their landmark closer than ``min_range`` (m) to the sensor are
    skipped (status :data:`TOO_CLOSE`; see :attr:`EkfMappingConfig.min_range`). Readings with
    an id update that landmark, or start it when it is not mapped yet (a
    landmark read twice in one scan is updated once per reading, in turn). Readings without
    an id are then associated with :func:`associate_nearest` (gates on ``νᵀ S⁻¹ ν``) and
    update, start a new landmark (ids continue after the largest mapped id) or are rejected.
    """
    model = require_invertible(model)
    x, za, R = check_reading_inputs(pose, z, noise_cov, model)
    rid = as_landmark_ids(ids, "ids", za.shape[0])
    if not (0 < gate <= new_gate):
        raise InputError(f"gates: expected 0 < gate <= new_gate, got {gate}, {new_gate}")
    if not (np.isfinite(min_range) and min_range >= 0):
        raise InputError(f"min_range: expected a number >= 0, got {min_range}")
    return process_readings_unchecked(
        belief, x, za, rid, R, model, gate, new_gate, float(min_range)
    )
