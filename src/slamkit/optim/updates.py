"""Feeding the incremental optimiser: a 2D pose graph split into time-ordered updates, and the
checks of an update's edges and guesses (:class:`~slamkit.optim.incremental.IncrementalOptimizer`
runs them on every :meth:`~slamkit.optim.incremental.IncrementalOptimizer.update`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from slamkit.errors import CovarianceError, InputError, NonFiniteError, ShapeError
from slamkit.optim.data import EdgeSet, FloatArray, GraphData, IntArray

__all__ = [
    "UPDATE_KINDS",
    "GraphUpdate",
    "check_guesses",
    "check_update_edges",
    "edge_name",
    "time_ordered_updates",
]

UPDATE_KINDS = ("se2", "se2_prior")
"""The edge kinds an update may carry."""


@dataclass(frozen=True)
class GraphUpdate:
    """One update: new pose ids (increasing), their edges, and optional initial guesses."""

    pose_ids: IntArray  # (K,)
    edges: tuple[EdgeSet, ...]
    initial_poses: FloatArray | None = None  # (K, 3); None: chained from the edges


def time_ordered_updates(data: GraphData, *, use_vertices: bool = False) -> list[GraphUpdate]:
    """Split a 2D pose graph into one update per pose in increasing id order, each carrying
    the edges (``se2``, ``se2_prior``) whose later end is that pose.

    ``use_vertices``: give the file's vertices as initial guesses (default: only the first
    pose's, where the gauge anchors it as in batch; the optimiser chains the others from the
    edges and its current estimate, as a robot would).
    """
    if data.dim != 2:
        raise InputError(f"incremental optimisation handles 2D pose graphs, got dim {data.dim}")
    sets = []
    for es in data.edges:
        if es.kind not in UPDATE_KINDS:
            raise InputError(
                f"incremental optimisation handles se2 and se2_prior edges, got {es.kind!r}"
            )
        sets.append(es)
    if data.poses.shape[0]:
        ids = np.asarray(data.pose_ids, dtype=np.int64)
    else:
        refs = [es.i for es in sets] + [es.j for es in sets if es.kind == "se2"]
        ids = np.unique(np.concatenate(refs)) if refs else np.zeros(0, np.int64)
    order = np.argsort(ids, kind="stable")
    sorted_ids = ids[order]
    per_set = []
    for es in sets:
        later = es.i if es.kind == "se2_prior" else np.maximum(es.i, es.j)
        k = np.argsort(later, kind="stable")
        starts = np.searchsorted(later[k], sorted_ids, side="left")
        ends = np.searchsorted(later[k], sorted_ids, side="right")
        per_set.append((es, k, starts, ends))
    updates = []
    for r, pid in enumerate(sorted_ids.tolist()):
        edges = []
        for es, k, starts, ends in per_set:
            sel = k[starts[r] : ends[r]]
            if sel.shape[0]:
                edges.append(
                    EdgeSet(
                        es.kind,
                        es.i[sel],
                        es.j[sel],
                        es.measurement[sel],
                        es.information[sel],
                        es.lines[sel] if es.lines.shape[0] else np.zeros(sel.shape[0], np.int64),
                    )
                )
        guess = None
        if data.poses.shape[0] and (use_vertices or r == 0):
            guess = data.poses[order[r]][None, :].copy()
        updates.append(GraphUpdate(np.array([pid], dtype=np.int64), tuple(edges), guess))
    return updates


def edge_name(es: EdgeSet, k: int) -> str:
    """``"se2 edge i → j (line L)"`` (or ``(#k of its set in this update)``) for messages."""
    line = int(es.lines[k]) if es.lines.shape[0] > k else 0
    what = f"{es.kind} edge {int(es.i[k])}" + (f" → {int(es.j[k])}" if es.kind == "se2" else "")
    return what + (f" (line {line})" if line > 0 else f" (#{k} of its set in this update)")


def check_guesses(initial_poses: FloatArray | None, ids: IntArray) -> FloatArray | None:
    """``initial_poses`` as ``(K, 3)`` floats for ``ids`` (``None`` stays ``None``); wrong
    shapes and NaN are errors naming the pose."""
    if initial_poses is None:
        return None
    g = np.asarray(initial_poses, dtype=np.float64)
    if g.shape != (ids.shape[0], 3):
        raise ShapeError(f"initial_poses: expected shape ({ids.shape[0]}, 3), got {g.shape}")
    if not np.isfinite(g).all():
        k = int(np.flatnonzero(~np.isfinite(g).all(axis=1))[0])
        raise NonFiniteError(f"initial_poses: NaN or infinity in the guess of pose {ids[k]}")
    return g


def check_update_edges(
    es: EdgeSet, whitening: Callable[[FloatArray], FloatArray | None] | None = None
) -> tuple[EdgeSet, FloatArray]:
    """Shapes, finiteness, symmetric positive definite information; returns ``U``.

    ``whitening(information)``: a faster way to ``U`` that returns ``None`` when a matrix
    fails these checks (the compiled one of :class:`~slamkit.optim.compiled2d.
    CompiledWindow`); the checks below then run and name the edge."""
    if es.kind not in UPDATE_KINDS:
        raise InputError(
            f"edge kind {es.kind!r}: incremental optimisation handles se2 and se2_prior"
        )
    n = len(es)
    for name, arr, shape in (
        ("j", es.j, (n,)),
        ("measurement", es.measurement, (n, 3)),
        ("information", es.information, (n, 3, 3)),
    ):
        if np.shape(arr) != shape:
            raise ShapeError(f"{es.kind} edges: {name} has shape {np.shape(arr)}, expected {shape}")
    info = es.information
    if not (np.isfinite(es.measurement).all() and np.isfinite(info).all()):
        bad = ~np.isfinite(es.measurement).all(axis=1) | ~np.isfinite(info).all(axis=(1, 2))
        raise NonFiniteError(f"{edge_name(es, int(np.flatnonzero(bad)[0]))}: NaN or infinity")
    if n == 0:
        return es, np.zeros((0, 3, 3))
    if whitening is not None and (U := whitening(info)) is not None:
        return es, U
    asym = np.abs(info - np.swapaxes(info, 1, 2)).max(axis=(1, 2)) > 1e-9 * np.abs(info).max(
        axis=(1, 2)
    )
    if asym.any():
        k = int(np.flatnonzero(asym)[0])
        raise CovarianceError(f"{edge_name(es, k)}: information matrix not symmetric")
    try:
        L = np.linalg.cholesky(info)
    except np.linalg.LinAlgError:
        k = int(np.argmin(np.linalg.eigvalsh(info).min(axis=1)))
        raise CovarianceError(
            f"{edge_name(es, k)}: information matrix not positive definite"
        ) from None
    return es, np.swapaxes(L, 1, 2)
