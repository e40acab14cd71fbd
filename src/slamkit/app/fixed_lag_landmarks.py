"""``slamkit optimize FILE --window L`` on a pose-landmark graph (iSAM's ``LANDMARK`` lines,
g2o's ``EDGE_SE2_XY``, range-bearing edges): the file streamed through
:class:`~slamkit.optim.fixed_lag_landmarks.LandmarkFixedLagSmoother`, called by
:func:`slamkit.app.fixed_lag.fixed_lag_job` when the graph holds landmarks.

Files written (``OUT`` the output folder), as for a pose graph where they exist:

* ``optimized.g2o`` — the graph at the smoother's estimate (poses and landmarks at their
  online estimates, the final window's at the final estimate);
* ``online.csv`` — ``id,x,y,theta``: each pose's estimate (as above);
* ``landmarks.csv`` — ``id,x,y``: each landmark's latest variable (a landmark seen again
  after it left the window is a new variable; the latest one is listed);
* ``graph.png`` — the arrival guesses and the smoother's estimate side by side;
* ``metrics.json`` — the pose graph's keys (``step_seconds``, ``iterations``,
  ``dropped_edges``, ``chi2_initial``, ``chi2_final`` over every edge, …) and
  ``landmarks``, ``reentries`` (observations of a landmark that had left),
  ``max_unknowns`` (the largest step system), ``max_prior_size`` (unknowns of the prior);
* ``config.json`` — the file and the :class:`~slamkit.optim.fixed_lag.FixedLagConfig`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from slamkit.config import config_to_dict
from slamkit.io import atomic_folder, write_json
from slamkit.io.landmarks import write_landmarks_csv
from slamkit.io.posegraph import write_graph
from slamkit.maps import LandmarkMap
from slamkit.optim import GraphData, g2o_chi2
from slamkit.optim.fixed_lag_landmarks import LandmarkFixedLagResult, smooth_landmark_fixed_lag

__all__ = ["has_landmarks", "landmark_fixed_lag_outputs", "step_statistics"]


def has_landmarks(data: GraphData) -> bool:
    """Whether ``data`` holds landmark variables or observation edges."""
    kinds = {e.kind for e in data.edges}
    return bool(data.landmark_ids.shape[0]) or bool(kinds & {"se2_xy", "range_bearing"})


def step_statistics(seconds: np.ndarray, iterations: np.ndarray) -> dict[str, Any]:
    """``step_seconds`` (median, p95, max, total) and ``iterations`` (mean, max) of a
    smoother's steps, as ``metrics.json`` holds them."""
    return {
        "step_seconds": {
            "median": float(np.median(seconds)),
            "p95": float(np.percentile(seconds, 95)),
            "max": float(seconds.max()),
            "total": float(seconds.sum()),
        },
        "iterations": {"mean": float(iterations.mean()), "max": int(iterations.max())},
    }


def _metrics(
    data: GraphData, path: Path, res: LandmarkFixedLagResult, seconds: dict[str, float]
) -> dict[str, Any]:
    t, its = res.step_seconds, res.step_iterations
    rows = np.searchsorted(res.pose_ids, _pose_order(data, res))
    return {
        "poses": int(res.pose_ids.shape[0]),
        "landmarks": int(res.landmark_ids.shape[0]),
        "edges": data.n_edges,
        "edges_by_kind": {e.kind: len(e) for e in data.edges},
        "window": res.window,
        "steps": res.steps,
        **step_statistics(t, its),
        "dropped_edges": {
            "count": res.dropped_edges,
            "why": "relative-pose edges to poses already marginalised out of the window",
            "first": [],
        },
        "reentries": res.reentries,
        "max_unknowns": res.max_unknowns,
        "max_prior_size": res.max_prior_size,
        "chi2_initial": g2o_chi2(data, res.initial_poses[rows], _lm(data, res, True)),
        "chi2_final": g2o_chi2(data, res.poses[rows], _lm(data, res, False)),
        "converged": res.converged,
        "finish_seconds": res.finish_seconds,
        **seconds,
        "input": {"file": str(path), "family": data.family},
    }


def _pose_order(data: GraphData, res: LandmarkFixedLagResult) -> np.ndarray:
    return data.pose_ids if data.poses.shape[0] else res.pose_ids


def _lm(data: GraphData, res: LandmarkFixedLagResult, initial: bool) -> np.ndarray:
    """Landmarks in the graph problem's order (the file's vertices, else sorted ids)."""
    values = res.initial_landmarks if initial else res.landmarks
    if not data.landmark_ids.shape[0]:
        return values
    return values[np.searchsorted(res.landmark_ids, data.landmark_ids)]


def landmark_fixed_lag_outputs(
    data: GraphData,
    path: Path,
    out_dir: Path,
    config: Any,
    *,
    plots: bool,
    overwrite: bool,
    read_seconds: float,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[tuple[str, ...], dict[str, Any], dict[str, Any], LandmarkFixedLagResult]:
    """Smooth ``data`` and write the files of the module docstring into ``out_dir``
    (atomically); returns the file names, metrics, resolved config and the result."""
    with atomic_folder(out_dir, overwrite=overwrite) as tmp:
        t1 = time.perf_counter()
        res = smooth_landmark_fixed_lag(data, config, progress)
        run_s = time.perf_counter() - t1
        metrics = _metrics(data, path, res, {"read_seconds": read_seconds, "run_seconds": run_s})
        resolved = {"file": str(path), "fixed_lag": config_to_dict(config)}
        order = _pose_order(data, res)
        rows = np.searchsorted(res.pose_ids, order)
        lm_ids = data.landmark_ids if data.landmark_ids.shape[0] else res.landmark_ids
        graph = dataclasses.replace(
            data, pose_ids=order.copy(), poses=res.poses[rows].copy(),
            landmark_ids=lm_ids.copy(), landmarks=_lm(data, res, False).copy(),
        )  # fmt: skip
        write_graph(graph, tmp / "optimized.g2o", family="g2o")
        metrics["output"] = {"graph_file": "optimized.g2o", "family": "g2o"}
        lines = [
            f"{pid},{float(p[0])!r},{float(p[1])!r},{float(p[2])!r}\n"
            for pid, p in zip(res.pose_ids.tolist(), res.poses, strict=True)
        ]
        (tmp / "online.csv").write_text("id,x,y,theta\n" + "".join(lines), encoding="utf-8")
        write_landmarks_csv(tmp / "landmarks.csv", LandmarkMap(res.landmarks, res.landmark_ids))
        write_json(tmp / "metrics.json", metrics)
        write_json(tmp / "config.json", resolved)
        if plots:
            from slamkit.viz import save_figure
            from slamkit.viz.graphs import pose_graph_figure

            fig = pose_graph_figure(
                res.initial_poses[:, :2],
                res.poses[:, :2],
                titles=(
                    f"guesses on arrival: χ² = {metrics['chi2_initial']:.6g}",
                    f"fixed-lag smoother (window {res.window}): χ² = {metrics['chi2_final']:.6g}",
                ),
                suptitle=f"{path.name}: {metrics['poses']} poses, {metrics['landmarks']} "
                f"landmarks, {res.reentries} re-entries",
            )
            save_figure(fig, tmp / "graph.png")
        files = tuple(sorted(p.name for p in tmp.iterdir()))
    return files, metrics, resolved, res
