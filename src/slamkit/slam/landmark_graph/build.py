"""A landmark data set as a factor graph: pose nodes, odometry edges integrated from the
controls, range-bearing edges of the associated readings, and (optionally) GPS fixes.

**Nodes.** One pose node at the start of the controls, at every readings event and at every
GPS fix (held-out fixes included, so they can be scored at their own time); node times that
coincide (to 1 µs) are one node. Node ``k`` has pose id ``k``; nodes are in time order.

**Odometry edges.** Every control ``(u, dt)`` covering ``[t - dt, t]`` is cut at the node
times inside it into pieces with the same ``u``. A piece's motion from the identity pose,
``Δ = g(0, u, dt)``, and its noise ``Q = V M Vᵀ`` (``V = ∂g/∂u`` at the identity, ``M`` the
data set's control covariance times ``motion_cov_scale``) are computed for all pieces at once
(the model is invariant to moving the start pose, so ``Δ`` is the piece's motion in the
frame of its start). The pieces between two nodes are chained from the identity,
``X ← X · Δ`` (``t ← t + R Δt``, ``θ ← θ + Δθ``), with the covariance of ``(x, y, θ)``
propagated to first order::

    Σ ← F Σ Fᵀ + G Q Gᵀ,   F = [[1, 0, -(R Δt)_y], [0, 1, (R Δt)_x], [0, 0, 1]],
                           G = diag(R, 1)

as the EKF's prediction does, one step per piece (so the graph and the filter see the same
odometry noise). The edge's measurement is the chained ``X`` and its information the inverse
of ``Σ`` expressed in the error's frame (g2o's error is a right perturbation of ``Z``:
``Σ_e = diag(Rᵀ, 1) Σ diag(R, 1)``) plus a floor (1 mm, 1e-4 rad standard deviations) that
keeps a segment without motion (the truck stopped) invertible. The pieces of all segments
advance together: one vectorised step per piece index.

**Readings.** Each reading of an associated landmark (id ≥ 0) is a ``range_bearing`` edge
with the sensor's covariance times ``measurement_cov_scale``. The graph takes the
association as given (the readings' ids): a data set without ids is refused.

**GPS** (:class:`GpsFixes`, optional). Each fix not held out is a ``gps`` edge (a
:mod:`slamkit.optim.gps` factor) from its node to the lever-arm variable, with covariance
``sigma² I`` or the fix's own; ``holdout_every = k`` keeps every ``k``-th fix (``k - 1``,
``2k - 1``, …) out of the graph for scoring.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray, as_covariance
from slamkit.datasets.gps_split import holdout_mask
from slamkit.datasets.stream import Control, Dataset, LandmarkReadings
from slamkit.errors import ConfigError, InputError
from slamkit.geometry.angles import wrap_angle
from slamkit.models.motion import motion_kernels
from slamkit.optim.data import EdgeSet, GraphData

__all__ = ["GpsFixes", "LandmarkGraph", "build_landmark_graph", "odometry_segments"]

IntArray = NDArray[np.int64]

_SAME_TIME = 1e-6  # [s] node times closer than this are one node
_FLOOR = np.diag([1e-3**2, 1e-3**2, 1e-4**2])  # covariance floor of an odometry edge


@dataclass(frozen=True)
class GpsFixes:
    """GPS fixes to fuse: times ``(M,)`` [s], positions ``(M, 2)`` [m] in the GPS frame."""

    times: FloatArray
    positions: FloatArray
    sigma: float = 1.0
    """Standard deviation of a fix, per axis [m]."""
    holdout_every: int = 0
    """Keep every ``k``-th fix out of the graph (0: use all)."""
    lever_arm: tuple[float, float] = (0.0, 0.0)
    """Initial lever arm (antenna in the robot frame) [m]; estimated by the graph."""
    covariances: FloatArray | None = None
    """Each fix's own covariance ``(M, 2, 2)`` [m²] (a receiver's reported accuracy), used
    instead of ``sigma² I`` when given."""

    def __post_init__(self) -> None:
        t = np.asarray(self.times, dtype=np.float64)
        p = np.asarray(self.positions, dtype=np.float64)
        if t.ndim != 1 or p.shape != (t.shape[0], 2):
            raise InputError(f"gps: times (M,) and positions (M, 2), got {t.shape}, {p.shape}")
        if not (np.isfinite(t).all() and np.isfinite(p).all()):
            raise InputError("gps: NaN or infinity in the fixes")
        if np.any(np.diff(t) <= 0):
            raise InputError("gps: expected increasing times")
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise ConfigError(f"gps sigma: expected a number > 0, got {self.sigma}")
        if self.holdout_every < 0 or self.holdout_every == 1:
            raise ConfigError(f"gps holdout_every: expected 0 or >= 2, got {self.holdout_every}")
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "positions", p)
        if self.covariances is not None:
            cov = as_covariance(self.covariances, "gps covariances", 2)
            if cov.shape != (t.shape[0], 2, 2):
                raise InputError(f"gps covariances: expected ({t.shape[0]}, 2, 2), got {cov.shape}")
            object.__setattr__(self, "covariances", cov)

    def information(self) -> FloatArray:
        """The information ``Σ⁻¹`` of every fix ``(M, 2, 2)``."""
        m = self.times.shape[0]
        if self.covariances is None:
            return np.tile(np.eye(2) / float(self.sigma) ** 2, (m, 1, 1))
        return np.asarray(np.linalg.inv(self.covariances), dtype=np.float64)

    @property
    def held_out(self) -> NDArray[np.bool_]:
        """Mask of the fixes kept out of the graph."""
        return holdout_mask(self.times.shape[0], self.holdout_every)


@dataclass(frozen=True)
class LandmarkGraph:
    """The graph and what relates it back to the data."""

    graph: GraphData
    times: FloatArray
    """Time of each pose node ``(N,)`` (pose id = row)."""
    initial_poses: FloatArray
    """Dead reckoning at the nodes ``(N, 3)``, from the data set's initial pose."""
    initial_landmarks: FloatArray
    """Each landmark (rows of ``graph.landmark_ids``) placed from its first reading through
    the dead-reckoned pose; the lever arm's row (when fused) at its initial value."""
    lever_id: int
    """Landmark id of the lever-arm variable (-1 without GPS)."""
    fix_nodes: IntArray
    """Node of every GPS fix ``(M,)`` (-1 for a fix outside the controls' span)."""
    fix_in_graph: NDArray[np.bool_]
    """Fixes that are ``gps`` edges (inside the span and not held out) ``(M,)``."""

    @property
    def map_ids(self) -> IntArray:
        """Ids of the landmarks proper (the lever arm left out)."""
        ids = self.graph.landmark_ids
        return ids[ids != self.lever_id]


def _controls(dataset: Dataset) -> tuple[FloatArray, FloatArray, FloatArray]:
    ctrl = [e for e in dataset.events if isinstance(e, Control)]
    if dataset.motion is None or dataset.motion.source != "control" or not ctrl:
        raise InputError(f"{dataset.name}: the landmark graph needs control events")
    ends = np.array([c.t for c in ctrl])
    dts = np.array([c.dt for c in ctrl])
    return ends - dts, ends, np.array([c.u for c in ctrl])


def odometry_segments(
    dataset: Dataset, node_times: FloatArray, motion_cov_scale: float = 1.0
) -> tuple[FloatArray, FloatArray]:
    """Relative poses ``(N - 1, 3)`` and their covariances ``(N - 1, 3, 3)`` (in the state's
    ``(x, y, θ)`` of the segment's start frame) between consecutive ``node_times``, integrated
    from ``dataset``'s controls (module docstring)."""
    starts, ends, u = _controls(dataset)
    spec = dataset.motion
    assert spec is not None
    kernels = motion_kernels(spec.model)
    cuts = np.union1d(np.union1d(starts, ends), node_times)
    cuts = cuts[(cuts >= starts[0]) & (cuts <= ends[-1])]
    a, b = cuts[:-1], cuts[1:]
    owner = np.searchsorted(ends, 0.5 * (a + b))  # the control whose interval holds the piece
    ok = (owner < ends.shape[0]) & (b - a > 0)
    a, b, owner = a[ok], b[ok], owner[ok]
    ok = starts[owner] <= a + _SAME_TIME  # a gap between controls has no motion
    a, b, owner = a[ok], b[ok], owner[ok]
    n_seg = node_times.shape[0] - 1
    seg = np.searchsorted(node_times, a + _SAME_TIME, side="right") - 1
    ok = (seg >= 0) & (seg < n_seg)
    a, b, owner, seg = a[ok], b[ok], owner[ok], seg[ok]
    dt = b - a
    zero = np.zeros((a.shape[0], 3))
    # One call for all pieces: the models' kernels broadcast an array of dt like the batch.
    dt_all = cast(float, dt)
    delta = kernels.apply_unchecked(zero, u[owner], dt_all)
    _, V = kernels.jacobians_unchecked(zero, u[owner], dt_all)
    M = spec.noise_cov * motion_cov_scale
    Q = V @ M @ np.swapaxes(V, 1, 2)
    # Position of each piece within its segment (pieces are in time order).
    first = np.searchsorted(seg, seg, side="left")
    pos = np.arange(seg.shape[0]) - first
    X = np.zeros((n_seg, 3))
    S = np.zeros((n_seg, 3, 3))
    for p in range(int(pos.max()) + 1 if pos.shape[0] else 0):
        rows = np.flatnonzero(pos == p)
        s = seg[rows]
        th = X[s, 2]
        c, sn = np.cos(th), np.sin(th)
        dx = c * delta[rows, 0] - sn * delta[rows, 1]  # R Δt
        dy = sn * delta[rows, 0] + c * delta[rows, 1]
        F = np.tile(np.eye(3), (rows.shape[0], 1, 1))
        F[:, 0, 2] = -dy
        F[:, 1, 2] = dx
        G = np.zeros((rows.shape[0], 3, 3))
        G[:, 0, 0] = G[:, 1, 1] = c
        G[:, 0, 1] = -sn
        G[:, 1, 0] = sn
        G[:, 2, 2] = 1.0
        S[s] = F @ S[s] @ np.swapaxes(F, 1, 2) + G @ Q[rows] @ np.swapaxes(G, 1, 2)
        X[s, 0] += dx
        X[s, 1] += dy
        X[s, 2] += delta[rows, 2]
    X[:, 2] = wrap_angle(X[:, 2])
    return X, 0.5 * (S + np.swapaxes(S, 1, 2))


def _chain(start: FloatArray, rel: FloatArray) -> FloatArray:
    """Poses from ``start (3,)`` by composing ``rel (N-1, 3)`` in turn."""
    out = np.empty((rel.shape[0] + 1, 3))
    out[0] = start
    for k in range(rel.shape[0]):
        c, s = np.cos(out[k, 2]), np.sin(out[k, 2])
        out[k + 1, 0] = out[k, 0] + c * rel[k, 0] - s * rel[k, 1]
        out[k + 1, 1] = out[k, 1] + s * rel[k, 0] + c * rel[k, 1]
        out[k + 1, 2] = out[k, 2] + rel[k, 2]
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def _node_times(dataset: Dataset, gps: GpsFixes | None) -> tuple[FloatArray, float, float]:
    starts, ends, _ = _controls(dataset)
    t0, t1 = float(starts[0]), float(ends[-1])
    reading_t = np.array([e.t for e in dataset.events if isinstance(e, LandmarkReadings)])
    parts = [np.array([t0]), reading_t]
    if gps is not None:
        parts.append(gps.times)
    t = np.unique(np.concatenate(parts))
    t = t[(t >= t0) & (t <= t1)]
    keep = np.concatenate([[True], np.diff(t) > _SAME_TIME])
    return t[keep], t0, t1


def _nearest_node(times: FloatArray, query: FloatArray) -> IntArray:
    k = np.clip(np.searchsorted(times, query), 1, times.shape[0] - 1)
    k = np.where(np.abs(times[k - 1] - query) <= np.abs(times[k] - query), k - 1, k)
    return k.astype(np.int64)


def _readings(
    dataset: Dataset, times: FloatArray, measurement_cov_scale: float
) -> tuple[EdgeSet, IntArray]:
    events = [e for e in dataset.events if isinstance(e, LandmarkReadings)]
    sensor = dataset.landmark_sensor
    if sensor is None or sensor.kind != "range-bearing" or not events:
        raise InputError(f"{dataset.name}: the landmark graph needs range-bearing readings")
    inside = [e for e in events if times[0] <= e.t <= times[-1]]
    z = np.concatenate([e.z for e in inside]).reshape(-1, 2)
    ids = np.concatenate([e.ids for e in inside]).astype(np.int64)
    if np.any(ids < 0):
        raise InputError(
            f"{dataset.name}: {int((ids < 0).sum())} readings without a landmark id; the "
            "landmark graph takes the association as given (load the data set with its ids)"
        )
    t = np.concatenate([np.full(e.ids.shape[0], e.t) for e in inside])
    nodes = _nearest_node(times, t)
    info = np.linalg.inv(sensor.noise_cov * measurement_cov_scale)
    edges = EdgeSet(
        "range_bearing",
        nodes,
        ids,
        z,
        np.tile(info, (ids.shape[0], 1, 1)),
        np.zeros(ids.shape[0], dtype=np.int64),
    )
    return edges, nodes


def _first_sightings(edges: EdgeSet, poses: FloatArray) -> tuple[IntArray, FloatArray]:
    ids, first = np.unique(edges.j, return_index=True)
    x = poses[edges.i[first]]
    r, b = edges.measurement[first, 0], edges.measurement[first, 1]
    lm = np.stack([x[:, 0] + r * np.cos(x[:, 2] + b), x[:, 1] + r * np.sin(x[:, 2] + b)], axis=1)
    return ids.astype(np.int64), lm


def build_landmark_graph(
    dataset: Dataset,
    *,
    gps: GpsFixes | None = None,
    motion_cov_scale: float = 1.0,
    measurement_cov_scale: float = 1.0,
) -> LandmarkGraph:
    """The factor graph of ``dataset`` (controls and associated range-bearing readings), with
    ``gps`` fused when given (module docstring)."""
    for name, v in (("motion", motion_cov_scale), ("measurement", measurement_cov_scale)):
        if not (np.isfinite(v) and v > 0):
            raise ConfigError(f"{name}_cov_scale: expected a number > 0, got {v}")
    times, t0, t1 = _node_times(dataset, gps)
    rel, cov = odometry_segments(dataset, times, motion_cov_scale)
    n = times.shape[0]
    R = np.zeros((n - 1, 3, 3))
    c, s = np.cos(rel[:, 2]), np.sin(rel[:, 2])
    R[:, 0, 0] = R[:, 1, 1] = c
    R[:, 0, 1] = s  # Rᵀ
    R[:, 1, 0] = -s
    R[:, 2, 2] = 1.0
    cov_e = R @ cov @ np.swapaxes(R, 1, 2) + _FLOOR
    pose_ids = np.arange(n, dtype=np.int64)
    odo = EdgeSet(
        "se2",
        pose_ids[:-1],
        pose_ids[1:],
        rel,
        np.asarray(np.linalg.inv(cov_e), dtype=np.float64),
        np.zeros(n - 1, dtype=np.int64),
    )
    readings, _ = _readings(dataset, times, measurement_cov_scale)
    start = np.zeros(3) if dataset.initial_pose is None else np.asarray(dataset.initial_pose)
    poses0 = _chain(start, rel)
    lm_ids, lm0 = _first_sightings(readings, poses0)
    edges = [odo, readings]
    lever_id = -1
    m = 0 if gps is None else gps.times.shape[0]
    fix_nodes = np.full(m, -1, dtype=np.int64)
    in_graph = np.zeros(m, dtype=bool)
    if gps is not None:
        inside = (gps.times >= t0) & (gps.times <= t1)
        fix_nodes[inside] = _nearest_node(times, gps.times[inside])
        in_graph = inside & ~gps.held_out
        lever_id = int(lm_ids.max()) + 1 if lm_ids.shape[0] else 0
        k = int(in_graph.sum())
        edges.append(
            EdgeSet(
                "gps",
                fix_nodes[in_graph],
                np.full(k, lever_id, dtype=np.int64),
                gps.positions[in_graph],
                gps.information()[in_graph],
                np.zeros(k, dtype=np.int64),
            )
        )
        lm_ids = np.append(lm_ids, lever_id)
        lm0 = np.vstack([lm0, np.asarray(gps.lever_arm, dtype=np.float64)])
    graph = GraphData(
        dim=2,
        pose_ids=pose_ids,
        poses=poses0,
        landmark_ids=lm_ids,
        landmarks=lm0,
        edges=tuple(edges),
        fixed_ids=np.array([0], dtype=np.int64) if gps is None else np.zeros(0, dtype=np.int64),
        source=dataset.name,
    )
    return LandmarkGraph(graph, times, poses0, lm0, lever_id, fix_nodes, in_graph)
