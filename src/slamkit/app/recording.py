"""A finished run as a rerun recording (``pip install 'slamkit[rerun]'``): a ``.rrd`` file or
a spawned viewer, on a ``time`` timeline in the data set's seconds.

Entities (all in metres, the world frame):

* ``world/estimate/path`` and ``world/truth/path`` — the whole paths (static line strips);
* ``world/estimate/pose`` — the pose at each time (one point per pose, with its heading
  as ``world/estimate/heading``), ``world/estimate/covariance`` — its 2σ ellipse;
* ``world/landmarks`` — the mapped landmarks with their ids (static), their 2σ ellipses
  ``world/landmarks/covariance``; ``world/truth/landmarks`` the true ones;
* ``world/scan`` — each laser scan's end points at the pose of its time;
* ``world/particles`` — the particle snapshots of a particle filter;
* ``world/graph/edges`` and ``world/graph/closures`` — the pose graph of an estimator that
  kept one: its edges between consecutive poses and its loop closures
  (:func:`~slamkit.optim.data.loop_closures`), static line segments (grey, red);
* ``world/map`` — the occupied cells (``OCCUPIED_THRESHOLD``) of the occupancy grid the run
  built, or else of the one it localized in (``Dataset.known_grid``: ``--map``), static
  points at the cell centres of radius half a cell.

The same run as an MCAP file for Foxglove: :mod:`slamkit.app.foxglove`.

rerun is imported only here, and only when a recording is made.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from slamkit.datasets.stream import Dataset, LaserScan
from slamkit.errors import InputError
from slamkit.geometry.pose2 import compose, interpolate_poses, transform_points
from slamkit.maps import OCCUPIED_THRESHOLD
from slamkit.models.laser import scan_points
from slamkit.optim.data import loop_closures
from slamkit.pipeline import Result

__all__ = ["MAX_ELLIPSES", "MAX_SCANS", "record_run", "require_rerun"]

MAX_SCANS = 2000
"""At most this many scans are logged (an even stride over the scans)."""
MAX_ELLIPSES = 1000
"""At most this many pose covariance ellipses are logged."""
TIMELINE = "time"


def require_rerun() -> Any:
    """The rerun module, or an :class:`InputError` saying how to install it."""
    try:
        import rerun
    except ImportError as exc:
        raise InputError(
            "a rerun recording needs the rerun-sdk package: pip install 'slamkit[rerun]'"
        ) from exc
    return rerun


def _ellipse(centre: np.ndarray, cov: np.ndarray, n: int = 32) -> np.ndarray:
    """The 2σ ellipse of the 2×2 ``cov`` around ``centre`` as ``(n + 1, 2)`` points."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    a = np.linspace(0.0, 2.0 * np.pi, n + 1)
    circle = np.column_stack([np.cos(a), np.sin(a)]) * (2.0 * np.sqrt(np.clip(vals, 0, None)))
    return np.asarray(centre + circle @ vecs.T, dtype=float)


def record_run(result: Result, dataset: Dataset, target: str | Path) -> None:
    """Log ``result`` (on ``dataset``) to rerun: ``target`` ``"spawn"`` opens a viewer,
    anything else is the path of the ``.rrd`` file to write."""
    rr = require_rerun()
    rec = rr.RecordingStream("slamkit", recording_id=f"{result.estimator}-{result.dataset}")
    if str(target) == "spawn":
        rec.spawn()
    else:
        rec.save(str(target))
    # rerun's 2D view draws y downward: one static flip of the world shows it y-up, while
    # every logged value stays the world coordinate
    rec.log("world", rr.Transform3D(mat3x3=[[1, 0, 0], [0, -1, 0], [0, 0, 1]]), static=True)
    times = np.asarray(result.times, dtype=float)
    poses = np.asarray(result.poses, dtype=float)
    if len(poses):
        rec.log("world/estimate/path", rr.LineStrips2D([poses[:, :2]]), static=True)
        cols = [rr.TimeColumn(TIMELINE, duration=times)]
        rec.send_columns(
            "world/estimate/pose", indexes=cols, columns=rr.Points2D.columns(positions=poses[:, :2])
        )
        heading = 0.5 * np.column_stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])])
        rec.send_columns(
            "world/estimate/heading",
            indexes=cols,
            columns=rr.Arrows2D.columns(origins=poses[:, :2], vectors=heading),
        )
    truth = dataset.truth
    if truth.poses is not None and len(truth.poses):
        rec.log("world/truth/path", rr.LineStrips2D([truth.poses[:, :2]]), static=True)
    if truth.landmarks is not None and len(truth.landmarks.positions):
        rec.log(
            "world/truth/landmarks",
            rr.Points2D(truth.landmarks.positions, labels=[str(i) for i in truth.landmarks.ids]),
            static=True,
        )
    if result.covariances is not None:
        covs = np.asarray(result.covariances, dtype=float)
        for k in np.unique(np.linspace(0, len(covs) - 1, min(MAX_ELLIPSES, len(covs))).astype(int)):
            rec.set_time(TIMELINE, duration=float(times[k]))
            strip = _ellipse(poses[k, :2], covs[k, :2, :2])
            rec.log("world/estimate/covariance", rr.LineStrips2D([strip]))
    estimate = result.output.landmarks
    if estimate is not None and len(estimate.landmarks.positions):
        lm = estimate.landmarks
        rec.log(
            "world/landmarks",
            rr.Points2D(lm.positions, labels=[str(i) for i in lm.ids]),
            static=True,
        )
        if estimate.covariances is not None:
            strips = [
                _ellipse(p, c) for p, c in zip(lm.positions, estimate.covariances, strict=True)
            ]
            rec.log("world/landmarks/covariance", rr.LineStrips2D(strips), static=True)
    laser = dataset.laser
    scans = [e for e in dataset.events if isinstance(e, LaserScan)]
    if laser is not None and scans and len(poses):
        for k in np.unique(np.linspace(0, len(scans) - 1, min(MAX_SCANS, len(scans))).astype(int)):
            scan = scans[int(k)]
            pts = scan_points(scan.ranges, laser.beam_angles, laser.max_range)
            robot = interpolate_poses(times, poses, np.array([scan.t]))[0]
            sensor = compose(robot, np.asarray(laser.mounting, dtype=float))
            rec.set_time(TIMELINE, duration=float(scan.t))
            rec.log("world/scan", rr.Points2D(transform_points(sensor, pts), radii=0.02))
    for snap in result.output.particle_snapshots:
        rec.set_time(TIMELINE, duration=float(snap.t))
        rec.log("world/particles", rr.Points2D(snap.particles[:, :2], radii=0.02))
    graph = result.output.graph
    if graph is not None and len(graph.poses):
        xy = graph.poses[:, :2]
        every = loop_closures(graph, min_gap=1)
        far = np.abs(every[:, 0] - every[:, 1]) >= 2
        for name, pairs, colour in (
            ("edges", every[~far], [140, 140, 140]),
            ("closures", every[far], [220, 30, 30]),
        ):
            rec.log(
                f"world/graph/{name}",
                rr.LineStrips2D(xy[pairs], colors=[colour]),
                static=True,
            )
    grid = result.output.grid if result.output.grid is not None else dataset.known_grid
    if grid is not None:
        rows, cols_ = np.nonzero(grid.prob >= OCCUPIED_THRESHOLD)
        centres = grid.origin_xy + (np.column_stack([cols_, rows]) + 0.5) * grid.resolution
        rec.log(
            "world/map",
            rr.Points2D(centres, radii=0.5 * grid.resolution, colors=[40, 40, 40]),
            static=True,
        )
    rec.flush()
    if str(target) != "spawn":
        rec.disconnect()
