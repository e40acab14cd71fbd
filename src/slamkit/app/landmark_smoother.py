"""``slamkit landmark-graph --window L``: a landmark data set's graph (its GPS left out)
smoothed over a sliding window of ``L`` nodes, beside the same graph solved in batch, both
scored against the GPS as EKF-SLAM is (:func:`slamkit.eval.gps.gps_error`: outliers rejected
from the track alone, SE(2)-aligned at every fix). Called by
:func:`slamkit.app.landmark_graph.landmark_graph_job` when the request has a window.

Files written (``OUT`` the output folder, complete or not at all):

* ``trajectory.tum`` — the smoother's online estimate of every node;
  ``trajectory_batch.tum`` — the batch solution of the same graph;
* ``landmarks.csv`` — the smoother's map (each landmark's latest variable);
* ``graph.png`` — the smoothed path and map over the GPS track;
* ``metrics.json`` — ``smoothed`` (counts, ``step_seconds`` median / p95 / max / total,
  ``reentries``, ``max_unknowns``, ``gps``), ``batch`` (counts, ``solve_seconds``, ``gps``),
  ``against_batch`` (translation RMSE and max of the online estimates against batch [m]);
* ``config.json`` — the request.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from slamkit.app.landmark_graph_types import LandmarkGraphReport, LandmarkGraphRequest
from slamkit.datasets.stream import Dataset
from slamkit.errors import ConfigError
from slamkit.eval.gps import gps_error
from slamkit.io import atomic_folder, write_json
from slamkit.io.landmarks import write_landmarks_csv
from slamkit.io.tum import write_tum
from slamkit.maps import LandmarkMap
from slamkit.optim.fixed_lag import FixedLagConfig
from slamkit.slam.landmark_graph import (
    GraphSolution,
    LandmarkGraphConfig,
    build_landmark_graph,
    smooth_graph,
    solve_unfused,
)

__all__ = ["smoothed_landmark_graph_job"]


def _gps(ds: Dataset, sol: GraphSolution) -> dict[str, Any] | None:
    t, xy = ds.truth.position_times, ds.truth.positions
    if t is None or xy is None:
        return None
    e = gps_error(sol.times, sol.poses, t, xy)
    return {"rmse": e.rmse, "median": e.median, "max": e.max, "fixes": e.count}


def smoothed_landmark_graph_job(
    request: LandmarkGraphRequest,
    ds: Dataset,
    progress: Callable[[int, int], None] | None = None,
) -> LandmarkGraphReport:
    """Build ``ds``'s graph without GPS, smooth it with ``request.window``, solve it in batch,
    score both and write the files of the module docstring."""
    if request.window is None or request.window < 1:
        raise ConfigError(f"window: expected an integer >= 1, got {request.window!r}")
    t0 = time.perf_counter()
    built = build_landmark_graph(ds)
    build_s = time.perf_counter() - t0
    smoothed, res = smooth_graph(built, FixedLagConfig(window=request.window), progress)
    batch = solve_unfused(built, LandmarkGraphConfig())
    d = np.hypot(*(smoothed.poses[:, :2] - batch.poses[:, :2]).T)
    t = res.step_seconds
    metrics: dict[str, Any] = {
        "data": request.data,
        "window": request.window,
        "build_seconds": build_s,
        "smoothed": {
            "poses": int(smoothed.poses.shape[0]),
            "landmarks": int(smoothed.landmark_ids.shape[0]),
            "step_seconds": {
                "median": float(np.median(t)),
                "p95": float(np.percentile(t, 95)),
                "max": float(t.max()),
                "total": float(t.sum()),
            },
            "reentries": res.reentries,
            "max_unknowns": res.max_unknowns,
            "max_prior_size": res.max_prior_size,
            "chi2": smoothed.chi2,
            "converged": smoothed.converged,
            "gps": _gps(ds, smoothed),
        },
        "batch": {
            "poses": int(batch.poses.shape[0]),
            "landmarks": int(batch.landmark_ids.shape[0]),
            "solve_seconds": batch.seconds,
            "chi2": batch.chi2,
            "converged": batch.converged,
            "gps": _gps(ds, batch),
        },
        "against_batch": {"rmse": float(np.sqrt(np.mean(d**2))), "max": float(d.max())},
    }
    figure = None
    if request.plots:
        from slamkit.viz.gps_fusion import plot_gps_fusion
        from slamkit.viz.plots import new_figure

        figure = new_figure(figsize=(8.0, 7.0))
        plot_gps_fusion(
            figure.add_subplot(), smoothed.poses, smoothed.landmarks, ds.truth.positions,
            label=f"fixed-lag window {request.window}",
        )  # fmt: skip
    config = {**dataclasses.asdict(request), "out_dir": str(request.out_dir)}
    config["data_root"] = None if request.data_root is None else str(request.data_root)
    with atomic_folder(request.out_dir, overwrite=request.overwrite) as tmp:
        write_tum(tmp / "trajectory.tum", smoothed.times, smoothed.poses)
        write_tum(tmp / "trajectory_batch.tum", batch.times, batch.poses)
        lm = LandmarkMap(smoothed.landmarks, smoothed.landmark_ids)
        write_landmarks_csv(tmp / "landmarks.csv", lm)
        write_json(tmp / "metrics.json", metrics)
        write_json(tmp / "config.json", config)
        if figure is not None:
            from slamkit.viz.plots import save_figure

            save_figure(figure, tmp / "graph.png", dpi=120)
        files = tuple(sorted(p.name for p in tmp.iterdir()))
    return LandmarkGraphReport(request.out_dir, files, metrics)
