"""Incremental pose-graph optimisation: slamkit's ``IncrementalOptimizer`` against GTSAM's
iSAM2 on intel and city10000, the same poses and edges fed in the same order, in one run.

The stream: one update per pose in id order, carrying the edges whose later end is that pose
(``slamkit.optim.incremental.time_ordered_updates``). Initial guesses follow one rule for
both: the first pose takes the file's vertex (both anchor it there: slamkit holds the first
pose fixed, GTSAM gets a ``PriorFactorPose2`` with σ = 1e-6); every later pose is the first
edge of its update that ties it to an earlier pose, composed with *that solver's* current
estimate of the earlier pose (GTSAM: ``calculateEstimatePose2`` of that pose, fetched outside
the timed call). GTSAM's factors are ``BetweenFactorPose2`` with
``noiseModel.Gaussian.Information`` of the edge's information; iSAM2 runs with default
``ISAM2Params`` (Gauss-Newton, relinearisation threshold 0.1, relinearise every 10 updates,
Cholesky). slamkit runs ``IncrementalConfig()`` defaults.

Timed per update: slamkit's whole ``update()`` call (validation, initial guess, window step,
batch steps when due); GTSAM's ``isam.update(factors, values)``. Not timed: building GTSAM's
factor objects, reading the file. At the end, the g2o objective ``χ² = Σ eᵀ Ω e`` of GTSAM's
``calculateEstimate()`` and of slamkit's estimate before and after its final batch step
(``finish()``, timed separately) are computed by ``slamkit.optim.g2o_chi2``; slamkit's final
poses are compared with batch ``optimize`` (Gauss-Newton to relative tolerance 1e-12) on the
whole graph.

Run: ``python benchmarks/bench_incremental.py`` or ``python benchmarks/run.py incremental``.
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from _common import Record, write_results
from slamkit.datasets import find_data_root
from slamkit.geometry import pose2
from slamkit.geometry.angles import wrap_angle
from slamkit.io.posegraph import read_graph
from slamkit.optim import OptimizerConfig, StoppingConfig, g2o_chi2, optimize
from slamkit.optim.incremental import (
    GraphUpdate,
    IncrementalConfig,
    IncrementalOptimizer,
    time_ordered_updates,
)

FILES = ["intel", "city10000"]
REPEATS = {"intel": 3, "city10000": 1}  # runs of each solver, interleaved; the fastest counts


def _stats(t: np.ndarray) -> str:
    return (
        f"{1e3 * t.mean():.3f} | {1e3 * np.median(t):.3f} | {1e3 * np.percentile(t, 99):.2f} "
        f"| {1e3 * t.max():.1f} | {t.sum():.2f}"
    )


def _guess_edge(update: GraphUpdate, pid: int) -> tuple[int, np.ndarray]:
    """The first edge of ``update`` tying pose ``pid`` to an earlier pose: ``(other, T)``
    with ``X_pid = X_other ⊕ T`` (slamkit's chaining rule)."""
    for es in update.edges:
        if es.kind != "se2":
            continue
        for i, j, z in zip(es.i.tolist(), es.j.tolist(), es.measurement, strict=True):
            if j == pid and i < pid:
                return i, z
            if i == pid and j < pid:
                return j, pose2.inverse(z)
    raise AssertionError(f"pose {pid} has no edge to an earlier pose")


def _run_slamkit(updates: list[GraphUpdate]) -> tuple[IncrementalOptimizer, np.ndarray]:
    inc = IncrementalOptimizer(IncrementalConfig())
    times = np.empty(len(updates))
    for k, u in enumerate(updates):
        t0 = time.perf_counter()
        inc.update(u.pose_ids, u.edges, u.initial_poses)
        times[k] = time.perf_counter() - t0
    return inc, times


def _run_gtsam(updates: list[GraphUpdate]) -> tuple[Any, np.ndarray]:
    import gtsam

    isam = gtsam.ISAM2(gtsam.ISAM2Params())
    times = np.empty(len(updates))
    for k, u in enumerate(updates):
        pid = int(u.pose_ids[0])
        fg = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        if k == 0:
            assert u.initial_poses is not None
            x0 = gtsam.Pose2(*u.initial_poses[0])
            fg.add(gtsam.PriorFactorPose2(pid, x0, gtsam.noiseModel.Isotropic.Sigma(3, 1e-6)))
            values.insert(pid, x0)
        else:
            other, z = _guess_edge(u, pid)
            values.insert(pid, isam.calculateEstimatePose2(other).compose(gtsam.Pose2(*z)))
        for es in u.edges:
            assert es.kind == "se2"
            for i, j, z, info in zip(
                es.i.tolist(), es.j.tolist(), es.measurement, es.information, strict=True
            ):
                noise = gtsam.noiseModel.Gaussian.Information(info)
                fg.add(gtsam.BetweenFactorPose2(i, j, gtsam.Pose2(*z), noise))
        t0 = time.perf_counter()
        isam.update(fg, values)
        times[k] = time.perf_counter() - t0
    return isam, times


def main() -> str:
    root = find_data_root()
    if root is None:
        raise SystemExit("data folder not found: set SLAMKIT_DATA")
    cfg = IncrementalConfig()
    records: list[Record] = []
    rows = [
        "| file | solver | mean [ms] | median [ms] | p99 [ms] | max [ms] | total [s] | final χ² |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    checks = []
    loads = [os.getloadavg()]
    for name in FILES:
        graph = read_graph(root / "posegraph2d" / f"{name}.g2o")
        updates = time_ordered_updates(graph)
        runs_ours, runs_peer = [], []
        for _ in range(REPEATS[name]):
            runs_ours.append(_run_slamkit(updates))
            loads.append(os.getloadavg())
            runs_peer.append(_run_gtsam(updates))
            loads.append(os.getloadavg())
        inc, t_ours = min(runs_ours, key=lambda run: float(run[1].sum()))
        isam, t_peer = min(runs_peer, key=lambda run: float(run[1].sum()))
        _, before = inc.estimate()
        chi2_before = g2o_chi2(graph, before)
        t0 = time.perf_counter()
        res = inc.finish()
        t_finish = time.perf_counter() - t0
        est = isam.calculateEstimate()
        g_poses = np.array(
            [[p.x(), p.y(), p.theta()] for p in (est.atPose2(int(k)) for k in res.pose_ids)]
        )
        chi2_peer = g2o_chi2(graph, g_poses)
        batch = optimize(
            graph, OptimizerConfig(solver="gn", stopping=StoppingConfig(relative_tolerance=1e-12))
        )
        assert np.array_equal(batch.pose_ids, res.pose_ids)
        diff = res.poses - batch.poses
        diff[:, 2] = wrap_angle(diff[:, 2])
        n = len(updates)
        records.append(
            Record(f"{name}: {n} updates, total", t_ours.sum(), "GTSAM iSAM2", t_peer.sum())
        )
        records.append(
            Record(
                f"{name}: median update",
                float(np.median(t_ours)),
                "GTSAM iSAM2",
                float(np.median(t_peer)),
            )
        )
        rows.append(
            f"| {name} | slamkit (estimate before finish) | {_stats(t_ours)} | {chi2_before:.8g} |"
        )
        rows.append(f"| {name} | slamkit finish() | | | | | {t_finish:.3f} | {res.chi2:.8g} |")
        rows.append(f"| {name} | GTSAM iSAM2 | {_stats(t_peer)} | {chi2_peer:.8g} |")
        checks.append(
            f"{name}: {n} poses, {graph.n_edges} edges; slamkit batch steps {res.batch_steps} "
            f"({res.batch_iterations} linearisations); final poses vs batch GN: max "
            f"|Δ| = {np.abs(diff).max():.2e}; batch χ² {batch.chi2:.8g}"
        )
    notes = "\n".join(
        [
            f"Runs per solver, interleaved, the fastest total kept: {REPEATS} (iSAM2 takes "
            f"minutes on city10000). slamkit config: {cfg}.",
            "Load average (1, 5, 15 min) at the start and after each run: "
            + ", ".join(f"({a:.1f}, {b:.1f}, {c:.1f})" for a, b, c in loads)
            + ".",
            "",
            *rows,
            "",
            *[f"* {c}" for c in checks],
        ]
    )
    return write_results("incremental", records, notes=notes)


if __name__ == "__main__":
    print(main())
