"""FastSLAM 1.0's measurement update: per-particle association (labelled rounds, greedy or
sequential maximum likelihood), landmark existence (misses, pruning) and weights."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.stream import LandmarkReadings
from slamkit.estimation.particles import (
    normalize_log_weights,
)
from slamkit.mapping.ekf_mapping import (
    DISCARDED,
    INITIALISED,
    UPDATED,
)
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.slam.fastslam.kernels import (
    innovation_pairs,
    landmark_ekf_update,
    landmark_terms,
    log_likelihood,
    new_landmarks,
    pose_planes,
    update_landmarks,
)
from slamkit.slam.fastslam.particles import NEGLIGIBLE_LOG_WEIGHT, IntArray
from slamkit.slam.fastslam.settings import UpdateSettings
from slamkit.slam.fastslam.store import MX, MY, Work


def _labelled_round(
    w: Work,
    poses: FloatArray,
    pose: tuple[FloatArray, FloatArray, FloatArray],
    z: FloatArray,
    rid: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    log_p0: float,
    mark: bool = True,
) -> tuple[FloatArray, NDArray[np.bool_] | None]:
    """Readings ``z (K, 2)`` of the distinct landmarks ``rid (K,)``, all at once: update the
    landmark with that id in every particle, or start it. Returns log-likelihoods ``(K, P)``
    (``log p0`` for a start, ``-inf`` for a landmark at the sensor) and which readings found
    their landmark ``(K, P)`` (None: all). ``mark``: see :func:`update_landmarks`."""
    n, k = poses.shape[0], z.shape[0]
    cmax = w.ids.shape[0] if w.slot_of is not None else int(w.counts.max())
    if cmax and (w.slot_of is not None or w.is_common(cmax)):
        # Every particle holds the same ids in the same slots (the usual case with labelled
        # readings only): look the ids up once, work on (K, P) blocks.
        where = w.slot_of
        if where is None:
            where = w.slot_of = {lid: j for j, lid in enumerate(w.ids[:cmax, 0].tolist())}
        slot_k = [where.get(lid, -1) for lid in rid.tolist()]
        if min(slot_k) >= 0:  # every id mapped
            slots = np.array(slot_k, dtype=np.intp)
            ll_all = update_landmarks(
                w, (slots, slice(None)), pose, z[:, 0:1], z[:, 1:2], R, model, mark
            )
            return ll_all, None
        kf = [j for j, sl in enumerate(slot_k) if sl >= 0]
        ll = np.full((k, n), log_p0)
        found = np.zeros((k, n), dtype=bool)
        if kf:
            slot = np.array([slot_k[j] for j in kf], dtype=np.intp)
            rows: Any = slice(None) if len(kf) == k else np.array(kf, dtype=np.intp)
            zf = z[rows]
            ll[rows] = update_landmarks(
                w, (slot, slice(None)), pose, zf[:, 0:1], zf[:, 1:2], R, model
            )
            found[rows] = True
        if len(kf) < k:
            new_landmarks(w, ~found, poses, z, rid, R, model)
            w.common = True  # every particle started the same ids in the same slots
        return ll, found
    ll = np.full((k, n), log_p0)
    found = np.zeros((k, n), dtype=bool)
    if cmax:
        valid = w.valid(cmax)
        hit = (w.ids[None, :cmax] == rid[:, None, None]) & valid  # (K, C, P)
        found = hit.any(axis=1)
        kr, pr = np.nonzero(found)
        if pr.size:
            slot = hit[kr, :, pr].argmax(axis=1)
            px, py, pth = pose
            ll[kr, pr] = update_landmarks(
                w, (slot, pr), (px[pr], py[pr], pth[pr]), z[kr, 0], z[kr, 1], R, model
            )
    new_landmarks(w, ~found, poses, z, rid, R, model)
    return ll, found


def labelled_rounds(rid: IntArray, index: NDArray[np.intp]) -> list[NDArray[np.intp]]:
    """Split the readings ``index`` into rounds of distinct ids, round ``r`` holding the
    ``r``-th reading of each id, each round in reading order."""
    if len(set(rid[index].tolist())) == index.size:  # the usual case: every id once
        return [index] if index.size else []
    rounds = []
    rest = index
    while rest.size:
        _, first = np.unique(rid[rest], return_index=True)
        if first.size == rest.size:
            rounds.append(rest)
            break
        take = np.zeros(rest.size, dtype=bool)
        take[first] = True
        rounds.append(rest[take])
        rest = rest[~take]
    return rounds


def _associate_greedy(ll_all: FloatArray, log_p0: float) -> tuple[NDArray[np.intp], FloatArray]:
    """Maximum-likelihood association of ``K`` readings, in order, in every particle:
    ``ll_all (K, C, P)`` log-likelihoods (``-inf``: not a candidate); a reading may not take
    a landmark an earlier reading of the scan took. Returns slots ``(K, P)`` (``-1``: new
    landmark) and log-likelihoods ``(K, P)`` (``log p0`` for a new landmark).

    Where the readings' unconstrained choices are distinct (the usual case) they are the
    greedy ones: by induction, no reading's best landmark was taken by an earlier one. Only
    the particles where two readings want the same landmark run the reading-by-reading
    loop."""
    k = ll_all.shape[0]
    best = np.argmax(ll_all, axis=1)  # (K, P)
    lb = np.take_along_axis(ll_all, best[:, None, :], axis=1)[:, 0]
    match = lb >= log_p0  # below p0 (or no candidate): a new landmark
    slots = np.where(match, best, -1)
    ll = np.where(match, lb, log_p0)
    if k > 1:
        key = np.sort(np.where(match, best, -1 - np.arange(k)[:, None]), axis=0)
        clash = np.flatnonzero((key[1:] == key[:-1]).any(axis=0))
        if clash.size:
            slots[:, clash], ll[:, clash] = _associate_sequential(ll_all[:, :, clash], log_p0)
    return slots, ll


def _associate_sequential(ll_all: FloatArray, log_p0: float) -> tuple[NDArray[np.intp], FloatArray]:
    """:func:`_associate_greedy` reading by reading (the exclusion applied as it goes)."""
    k, c, n = ll_all.shape
    cols = np.arange(n)
    taken = np.zeros((c, n), dtype=bool)
    slots = np.full((k, n), -1, dtype=np.intp)
    ll = np.full((k, n), log_p0)
    for j in range(k):
        llk = np.where(taken, -np.inf, ll_all[j])
        best = np.argmax(llk, axis=0)
        lb = llk[best, cols]
        match = lb >= log_p0
        p = cols[match]
        slots[j, p] = best[match]
        ll[j, p] = lb[match]
        taken[best[match], p] = True
    return slots, ll


def _unlabelled(
    w: Work,
    poses: FloatArray,
    pose: tuple[FloatArray, FloatArray, FloatArray],
    z: FloatArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    log_p0: float,
    forced: NDArray[np.intp] | None = None,
) -> tuple[FloatArray, IntArray, NDArray[np.int8]]:
    """Unlabelled readings ``z (K, 2)``: associate each in every particle by maximum
    likelihood (excluding landmarks already used in this scan) or take the ``forced`` slots
    ``(K, P)`` (``-1`` new, ``-2`` skip); update or start the landmarks, all at once.
    Returns the log-likelihoods ``(K, P)`` (meaningless with ``forced``), and the id of the
    landmark each reading updated or started with its status code ``(K, P)`` (see
    :meth:`FastSlam1.reading_log`)."""
    n, k = poses.shape[0], z.shape[0]
    cmax = int(w.counts.max())
    if forced is None:
        slots = np.full((k, n), -1, dtype=np.intp)
        ll = np.full((k, n), log_p0)
        if cmax:
            # The terms of the landmarks do not depend on the reading: (C, P) once, then the
            # innovations and likelihoods of every (reading, landmark, particle).
            F, ok = landmark_terms(model, pose, w.lm[:, :cmax], R)
            Fb = F[:, None]
            nu0, nu1 = innovation_pairs(model, Fb, z[:, 0, None, None], z[:, 1, None, None])
            cand = w.valid(cmax) & ok & ~w.seen[:cmax]
            ll_all = log_likelihood(Fb, nu0, nu1)
            ll_all[:, ~cand] = -np.inf
            slots, ll = _associate_greedy(ll_all, log_p0)
            kr, pr = np.nonzero(slots >= 0)
            if pr.size:
                sl = slots[kr, pr]
                g = w.lm[:, sl, pr]
                w.lm[:, sl, pr] = landmark_ekf_update(
                    F[:, sl, pr], g, nu0[kr, sl, pr], nu1[kr, sl, pr], R
                )
                w.seen[sl, pr] = True
                w.updated[sl, pr] = True
    else:
        slots, ll = forced, np.zeros((k, n))
        kr, pr = np.nonzero(slots >= 0)
        if pr.size:
            px, py, pth = pose
            update_landmarks(
                w, (slots[kr, pr], pr), (px[pr], py[pr], pth[pr]), z[kr, 0], z[kr, 1], R,
                model,
            )  # fmt: skip
    new = slots == -1
    matched = slots >= 0
    assoc = np.full((k, n), -1, dtype=np.int64)
    status = np.full((k, n), DISCARDED, dtype=np.int8)
    kr, pr = np.nonzero(matched)
    assoc[kr, pr] = w.ids[slots[kr, pr], pr]  # before new landmarks or pruning move slots
    status[matched] = UPDATED
    spawning = new.any(axis=1)  # readings that start a landmark somewhere get one id each
    if spawning.any():
        w.maybe_prunable = True
        ids = np.full(k, -1, dtype=np.int64)
        ids[spawning] = w.next_id + np.arange(int(spawning.sum()))
        w.next_id += int(spawning.sum())
        new_landmarks(w, new, poses, z, ids, R, model)
        assoc[new] = np.broadcast_to(ids[:, None], (k, n))[new]
        status[new] = INITIALISED
    return ll, assoc, status


def split_labelled(rid: IntArray, s: UpdateSettings) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices of the labelled readings (ids used) and of the unlabelled ones."""
    lab = (rid >= 0) if s.use_ids else np.zeros(rid.size, dtype=bool)
    return np.flatnonzero(lab), np.flatnonzero(~lab)


def scan_at_poses(
    w: Work,
    poses: FloatArray,
    z: FloatArray,
    rid: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    s: UpdateSettings,
    *,
    forced_unlabelled: NDArray[np.intp] | None = None,
    weigh_first_round: bool = True,
) -> FloatArray:
    """One scan at given particle poses (FastSLAM 1.0, and 2.0 after sampling): labelled
    readings first (in rounds of distinct ids), then the unlabelled ones. Returns each
    particle's log-likelihood of the readings ``(P,)`` — for 2.0 (``forced_unlabelled``
    ``(K_unlabelled, P)`` given, ``weigh_first_round`` False) only of the readings its
    proposal left out."""
    pose = pose_planes(poses)
    ids = rid.tolist()
    if s.use_ids and ids and min(ids) >= 0 and len(set(ids)) == len(ids):
        # The usual case with known correspondences: every reading labelled, each id once.
        # Labelled landmarks keep no existence counter and no unlabelled reading follows:
        # nothing reads the seen/updated marks of this scan.
        w.all_ok = True
        l_all, found = _labelled_round(w, poses, pose, z, rid, R, model, s.log_p0, mark=False)
        if found is None and w.all_ok:  # every particle: every reading updated
            w.assoc, w.assoc_status = rid, np.empty(rid.size, dtype=np.int8)
            w.assoc_status.fill(UPDATED)  # (np.full costs 3x: a Python wrapper)
        else:
            w.assoc, w.assoc_status = _labelled_association(rid, found, l_all == -np.inf)
        return l_all.sum(axis=0) if weigh_first_round else np.zeros(poses.shape[0])
    n, k = poses.shape[0], rid.size
    assoc = np.full((k, n), -1, dtype=np.int64)
    status = np.full((k, n), DISCARDED, dtype=np.int8)
    ll = np.zeros(n)
    lab, unl = split_labelled(rid, s)
    for r, idx in enumerate(labelled_rounds(rid, lab)):
        l_round, found = _labelled_round(w, poses, pose, z[idx], rid[idx], R, model, s.log_p0)
        assoc[idx], status[idx] = _labelled_association(rid[idx], found, l_round == -np.inf)
        if r > 0 or weigh_first_round:
            ll += l_round.sum(axis=0)
    if unl.size:
        l_unl, assoc[unl], status[unl] = _unlabelled(
            w, poses, pose, z[unl], R, model, s.log_p0, forced_unlabelled
        )
        if forced_unlabelled is None:
            ll += l_unl.sum(axis=0)
    w.assoc, w.assoc_status = assoc, status
    return ll


def _labelled_association(
    rid: IntArray, found: NDArray[np.bool_] | None, at_sensor: NDArray[np.bool_]
) -> tuple[IntArray, NDArray[np.int8]]:
    """Ids and status codes ``(K, P)`` of labelled readings: the reading's id, updated where
    the landmark was found (discarded where it was at the sensor), started elsewhere."""
    k, n = at_sensor.shape
    status = np.full((k, n), UPDATED if found is None else INITIALISED, dtype=np.int8)
    if found is not None:
        status[found] = UPDATED
    status[at_sensor] = DISCARDED
    assoc = np.where(at_sensor, -1, rid[:, None])
    return assoc, status


def predicted_visible(
    x: FloatArray, y: FloatArray, poses: FloatArray, s: UpdateSettings
) -> NDArray[np.bool_]:
    """Which landmarks at world positions ``(x, y)`` ``(C, P)`` the sensor should see from
    the particles' poses ``(P, 3)``: range from the sensor within ``[visible_min_range,
    visible_max_range]`` and bearing from the sensor within ``±fov/2`` of the heading, the
    sensor sitting at ``sensor_offset`` in the robot frame.

    The offset matters where it is large beside the ranges: Victoria Park's laser sits 3.78
    m ahead of the rear axle, the pose's origin, and sees only the half-plane ahead of
    itself; judged from the axle, the trees beside the cab (between axle and laser) would
    count as missed at every scan. (A candidate for a method of the sensor specification,
    next to the simulator's visibility test, once the specification carries the offset.)"""
    px, py, pth = pose_planes(poses)
    dx, dy = x - px, y - py
    a, b = s.sensor_offset
    limited_fov = s.fov < 2.0 * math.pi
    if limited_fov or a or b:
        c, sn = np.cos(pth), np.sin(pth)
        xs, ys = c * dx + sn * dy - a, c * dy - sn * dx - b  # in the sensor frame
        if a or b:  # (without an offset the world-frame range is the same)
            dx, dy = xs, ys
    r2 = dx * dx
    r2 += dy * dy
    visible = r2 >= s.visible_min_range**2
    if math.isfinite(s.visible_max_range):
        visible &= r2 <= s.visible_max_range**2
    if limited_fov:
        visible &= np.abs(np.arctan2(ys, xs)) <= 0.5 * s.fov
    return visible


def prune_landmarks(w: Work, poses: FloatArray, s: UpdateSettings) -> None:
    """End of a scan, for the landmarks that can be removed (started by unlabelled readings,
    ``prune`` on; the others keep no counter): existence counters up for updated landmarks,
    down for landmarks predicted visible but not seen; remove those below zero (stable
    compaction)."""
    if not (s.prune and w.maybe_prunable):
        return
    cmax = int(w.counts.max()) if w.counts.size else 0
    if cmax == 0:
        return
    prunable = w.ids[:cmax] >= s.first_unlabelled_id  # (unused slots hold id -1)
    if not prunable.any():
        return
    visible = prunable & predicted_visible(w.lm[MX, :cmax], w.lm[MY, :cmax], poses, s)
    counters = w.counters[:cmax]
    hits = w.updated[:cmax] & prunable
    counters += hits if s.hit_weight == 1 else s.hit_weight * hits  # views: in place
    counters -= visible & ~w.seen[:cmax]
    remove = prunable & (counters < 0)
    if not remove.any():
        return
    w.removed += int(remove.sum())
    keep = w.valid(cmax) & ~remove
    order = np.argsort(~keep, axis=0, kind="stable")  # kept slots first, in their order
    w.lm[:, :cmax] = np.take_along_axis(w.lm[:, :cmax], order[None], axis=1)
    w.counters[:cmax] = np.take_along_axis(counters, order, axis=0)
    w.ids[:cmax] = np.take_along_axis(w.ids[:cmax], order, axis=0)
    w.counts = keep.sum(axis=0).astype(np.int64)
    unused = ~w.valid()
    w.ids[unused] = -1
    w.counters[unused] = 0
    w.common = None


def usable_readings(
    z: FloatArray, model: InvertibleLandmarkModel, s: UpdateSettings
) -> NDArray[np.bool_]:
    if s.min_range <= 0 or z.shape[0] == 0:
        return np.ones(z.shape[0], dtype=bool)
    lm = model.inverse(np.zeros(3), z)  # the landmark in the robot frame
    return np.asarray(np.hypot(lm[:, 0], lm[:, 1]) >= s.min_range)


def normalised_log_weights(log_weights: FloatArray) -> FloatArray:
    """Log-weights minus their log-sum-exp; ConvergenceError if every weight is zero or one
    is NaN (:func:`normalize_log_weights`, called for its errors only on that path)."""
    m = float(log_weights.max())
    if not math.isfinite(m):
        lw, _ = normalize_log_weights(log_weights)  # raises: all zero, NaN or +inf
        return lw
    return log_weights - (m + math.log(float(np.sum(np.exp(log_weights - m)))))


def normalised_with_weights(log_weights: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`normalised_log_weights` and :func:`_weights_of` at once (one exponential)."""
    m = float(log_weights.max())
    if not math.isfinite(m):
        lw = normalised_log_weights(log_weights)  # raises: all zero, NaN or +inf
        return lw, _weights_of(lw)
    d = log_weights - m
    e = np.exp(d)
    total = float(e.sum())
    d -= math.log(total)
    e /= total
    if float(d.min()) <= NEGLIGIBLE_LOG_WEIGHT:
        e[d <= NEGLIGIBLE_LOG_WEIGHT] = 0.0
        e /= e.sum()
    return d, e


def _weights_of(log_weights: FloatArray) -> FloatArray:
    """Normalised weights; log-weights below ``-700`` give exactly 0 (see
    :attr:`FastSlamParticles.weights`)."""
    w: FloatArray = np.zeros(log_weights.shape)
    np.exp(log_weights, out=w, where=log_weights > NEGLIGIBLE_LOG_WEIGHT)
    w /= w.sum()
    return w


def update1(
    w: Work,
    poses: FloatArray,
    log_weights: FloatArray,
    z: FloatArray,
    rid: IntArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
    s: UpdateSettings,
) -> tuple[FloatArray, FloatArray]:
    """FastSLAM 1.0's scan on the maps ``w`` (in place) at ``poses``: the new normalised
    log-weights and each particle's log-likelihood of the scan ``(P,)``."""
    w.begin_scan()
    ll = scan_at_poses(w, poses, z, rid, R, model, s)
    prune_landmarks(w, poses, s)
    return normalised_log_weights(log_weights + ll), ll


def kept_readings(
    event: LandmarkReadings, model: InvertibleLandmarkModel, s: UpdateSettings
) -> tuple[FloatArray, IntArray, NDArray[np.bool_] | None]:
    """A scan's readings ``z``, ids and the mask of those kept (None: all): readings that
    place their landmark closer than ``s.min_range`` to the sensor are skipped."""
    z = np.asarray(event.z, dtype=float)
    rid = np.asarray(event.ids, dtype=np.int64)
    if s.min_range <= 0:
        return z, rid, None
    use = usable_readings(z, model, s)
    if use.all():
        return z, rid, None
    return z[use], rid[use], use
