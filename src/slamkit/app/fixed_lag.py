"""``fixed_lag_job``: a 2D pose-graph file streamed through the fixed-lag smoother
(``slamkit optimize FILE --window L``), its outputs in one folder written completely or not
at all. A graph with landmarks goes to :mod:`slamkit.app.fixed_lag_landmarks` (its files
are listed there).

Files written (``OUT`` the output folder):

* ``optimized.g2o`` or ``optimized.graph`` — the graph with every vertex at the smoother's
  estimate: a pose that left the window at its online estimate (its value when it was
  marginalised), the final window's poses at the final window estimate; the input's family
  when it holds vertices (g2o, TORO), else g2o, as ``slamkit optimize`` writes.
* ``online.csv`` — ``id,x,y,theta,step``: each pose's online estimate and the step (1-based,
  one pose a step) at which it left the window; the first pose, when it anchors the gauge,
  is listed at step 0 at its fixed value.
* ``window.csv`` — ``id,x,y,theta``: the final window estimate.
* ``graph.png`` — each pose's guess on arrival and the smoother's estimate, side by side.
* ``metrics.json`` — counts, ``window``, ``step_seconds`` (``median``, ``p95``, ``max``,
  ``total``: wall time of each step), ``iterations`` per step (``mean``, ``max``),
  ``dropped_edges`` (the loop closures to poses already marginalised out: ``count`` and the
  first ones as ``file:line``), ``max_prior_poses``, ``chi2_initial`` (the arrival guesses)
  and ``chi2_final`` (the smoother's estimate) over every edge of the file, ``window_chi2``
  (the final window's edges and prior), ``converged`` (the last window), the times.
* ``config.json`` — the file and :class:`~slamkit.optim.fixed_lag.FixedLagConfig`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from slamkit.app.fixed_lag_landmarks import (
    has_landmarks,
    landmark_fixed_lag_outputs,
    step_statistics,
)
from slamkit.config import config_to_dict
from slamkit.io import atomic_folder, write_json
from slamkit.io.posegraph import read_graph, write_graph
from slamkit.optim import GraphData, g2o_chi2
from slamkit.optim.fixed_lag import FixedLagConfig, FixedLagResult, smooth_fixed_lag
from slamkit.optim.fixed_lag_landmarks import LandmarkFixedLagResult

if TYPE_CHECKING:
    from slamkit.viz.plots import Figure  # app never imports matplotlib itself

__all__ = ["FixedLagReport", "FixedLagRequest", "fixed_lag_job"]


@dataclass(frozen=True)
class FixedLagRequest:
    """The options of one ``slamkit optimize FILE --window L`` run."""

    path: Path
    """The 2D pose-graph file (g2o, TORO/hog-man ``.graph``, iSAM/GTSAM ``.txt``)."""
    out_dir: Path
    """The output folder (written atomically; an existing non-empty one needs ``overwrite``)."""
    config: FixedLagConfig
    plots: bool = True
    overwrite: bool = False


@dataclass(frozen=True)
class FixedLagReport:
    """What :func:`fixed_lag_job` wrote and measured."""

    out_dir: Path
    files: tuple[str, ...]
    metrics: dict[str, Any]
    config: dict[str, Any]
    result: FixedLagResult | LandmarkFixedLagResult


def _in_file_order(data: GraphData, result: FixedLagResult) -> tuple[np.ndarray, np.ndarray]:
    """``(pose_ids, rows)``: the graph's pose order (its vertices', else sorted ids) and the
    result's row of each."""
    if data.poses.shape[0] == 0:
        return result.pose_ids, np.arange(result.pose_ids.shape[0])
    return data.pose_ids, np.searchsorted(result.pose_ids, data.pose_ids)


def _write_csv(path: Path, header: str, rows: list[str]) -> None:
    path.write_text(header + "\n" + "".join(r + "\n" for r in rows), encoding="utf-8")


def _pose_rows(ids: np.ndarray, poses: np.ndarray, extra: np.ndarray | None = None) -> list[str]:
    rows = []
    for k, (pid, p) in enumerate(zip(ids.tolist(), poses, strict=True)):
        row = f"{pid},{float(p[0])!r},{float(p[1])!r},{float(p[2])!r}"
        rows.append(row if extra is None else f"{row},{int(extra[k])}")
    return rows


def _metrics(
    data: GraphData, path: Path, result: FixedLagResult, seconds: dict[str, float]
) -> dict[str, Any]:
    _, rows = _in_file_order(data, result)
    t = result.step_seconds
    its = result.step_iterations
    return {
        "poses": int(result.pose_ids.shape[0]),
        "edges": data.n_edges,
        "edges_by_kind": {e.kind: len(e) for e in data.edges},
        "window": result.window,
        "steps": result.steps,
        **step_statistics(t, its),
        "dropped_edges": {
            "count": result.dropped_edges,
            "why": "loop closures to poses already marginalised out of the window",
            "first": [f"{path}:{int(line)}" for line in result.dropped_lines if line > 0],
        },
        "max_prior_poses": result.max_prior_poses,
        "anchored_first_pose": result.anchored_first,
        "chi2_initial": g2o_chi2(data, result.initial_poses[rows]),
        "chi2_final": g2o_chi2(data, result.poses[rows]),
        "window_chi2": result.window_chi2,
        "converged": result.converged,
        "finish_seconds": result.finish_seconds,
        **seconds,
        "input": {"file": str(path), "family": data.family},
    }


def _output_graph(data: GraphData, result: FixedLagResult) -> tuple[GraphData, str, str]:
    """The graph at the smoother's estimate, its family and its file name."""
    ids, rows = _in_file_order(data, result)
    family = data.family if data.family in ("g2o", "toro") else "g2o"
    graph = dataclasses.replace(data, pose_ids=ids.copy(), poses=result.poses[rows].copy())
    return graph, family, "optimized" + (".graph" if family == "toro" else ".g2o")


def _edge_rows(data: GraphData, result: FixedLagResult) -> np.ndarray:
    """``(E, 2)`` result rows of the relative-pose edges, for the plot."""
    pairs = [np.column_stack([e.i, e.j]) for e in data.edges if e.kind == "se2"]
    if not pairs:
        return np.zeros((0, 2), dtype=np.int64)
    return np.searchsorted(result.pose_ids, np.concatenate(pairs))


def _figure(data: GraphData, path: Path, result: FixedLagResult, m: dict[str, Any]) -> Figure:
    from slamkit.viz.graphs import pose_graph_figure  # plotting only when asked

    return pose_graph_figure(
        result.initial_poses[:, :2],
        result.poses[:, :2],
        edges=_edge_rows(data, result),
        titles=(
            f"guesses on arrival: χ² = {m['chi2_initial']:.6g}",
            f"fixed-lag smoother (window {result.window}): χ² = {m['chi2_final']:.6g}",
        ),
        suptitle=f"{path.name}: {m['poses']} poses, {m['edges']} edges, "
        f"{result.dropped_edges} dropped",
    )


def fixed_lag_job(
    request: FixedLagRequest, progress: Callable[[int, int], None] | None = None
) -> FixedLagReport:
    """Read ``request.path``, stream it through the smoother and write the files of the
    module docstring into ``request.out_dir``. ``progress(step, steps)`` runs after every
    step.

    A malformed file raises :class:`~slamkit.errors.DatasetFormatError` naming the file and
    line; a graph the smoother cannot take (3D, fixed vertices beyond the first)
    an :class:`~slamkit.errors.InputError`; an existing non-empty output folder without
    ``overwrite`` an :class:`~slamkit.errors.InputError`. Nothing is written then.
    """
    path = Path(request.path)
    t0 = time.perf_counter()
    data = read_graph(path)
    t1 = time.perf_counter()
    if has_landmarks(data):  # a pose-landmark graph: its own smoother and files
        files, m, resolved, res = landmark_fixed_lag_outputs(
            data, path, request.out_dir, request.config, plots=request.plots,
            overwrite=request.overwrite, read_seconds=t1 - t0, progress=progress,
        )  # fmt: skip
        return FixedLagReport(Path(request.out_dir), files, m, resolved, res)
    with atomic_folder(request.out_dir, overwrite=request.overwrite) as tmp:
        result = smooth_fixed_lag(data, request.config, progress)
        t2 = time.perf_counter()
        metrics = _metrics(data, path, result, {"read_seconds": t1 - t0, "run_seconds": t2 - t1})
        graph, family, name = _output_graph(data, result)
        resolved = {"file": str(path), "fixed_lag": config_to_dict(request.config)}
        metrics["output"] = {"graph_file": name, "family": family}
        write_graph(graph, tmp / name, family=family)  # type: ignore[arg-type]
        online = result.left_at_step > 0
        if result.anchored_first:
            online[0] = True
        _write_csv(
            tmp / "online.csv",
            "id,x,y,theta,step",
            _pose_rows(result.pose_ids[online], result.poses[online], result.left_at_step[online]),
        )
        _write_csv(
            tmp / "window.csv", "id,x,y,theta", _pose_rows(result.window_ids, result.window_poses)
        )
        write_json(tmp / "metrics.json", metrics)
        write_json(tmp / "config.json", resolved)
        if request.plots:
            from slamkit.viz import save_figure

            save_figure(_figure(data, path, result, metrics), tmp / "graph.png")
        files = tuple(sorted(p.name for p in tmp.iterdir()))
    return FixedLagReport(Path(request.out_dir), files, metrics, resolved, result)
