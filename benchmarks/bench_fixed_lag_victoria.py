"""Fixed-lag smoothing of Victoria Park's pose-landmark graph: slamkit's
``LandmarkFixedLagSmoother`` against GTSAM's ``BatchFixedLagSmoother`` and iSAM2 fed the same
stream, and the smoothed path's GPS RMSE beside EKF-SLAM's (the Victoria Park part of
``bench_fixed_lag.py``, in its own file and results):
``python benchmarks/bench_fixed_lag_victoria.py`` or ``python benchmarks/run.py
fixed_lag_victoria``.

**The stream** is the landmark graph of the Victoria Park data set with its feature index as
the association (``slamkit.slam.landmark_graph.build_landmark_graph`` without GPS: a node at
every readings event, odometry integrated between nodes, ``range_bearing`` edges), one step
per node in time order with its odometry edge and its readings (``landmark_updates``). The
first node is the anchor (slamkit holds it fixed; GTSAM gets a ``PriorFactorPose2`` of σ
``ANCHOR_SIGMA``). GTSAM's factors: ``BetweenFactorPose2`` and ``BearingRangeFactor2D``
with ``noiseModel.Gaussian.Information`` of the edge (its rows permuted to GTSAM's (bearing,
range) order). A landmark's first guess: its first reading from the new node's guess (the
node's own guess: the odometry edge from the previous node's current estimate in that
solver).

**Landmarks in GTSAM's window.** Each landmark key is stamped with the step of its latest
reading, so ``BatchFixedLagSmoother(lag=L)`` keeps it while a reading is within the lag, as
slamkit keeps it while a window node observes it. A landmark that GTSAM has marginalised and
that is read again gets a new key, as slamkit re-enters it as a new variable. iSAM2 keeps the
whole graph (one key per landmark).

GTSAM's ``BatchFixedLagSmoother`` factorises by QR: with its default Cholesky it stops with
an "indeterminate linear system" near node 6026 (window 10); iSAM2 runs with Cholesky.

**Timed per step**: slamkit's ``update()``; GTSAM's ``smoother.update`` / ``isam.update``.
**Error** of each node's online estimate (its estimate ``L`` steps after it arrived; the last
``L``: the final estimate) against slamkit's batch solution of the whole graph (same anchor;
``solve_unfused``: solves over growing prefixes, as ``slamkit landmark-graph`` solves it).
**GPS**: every solver's online path scored like EKF-SLAM (``slamkit.eval.gps.gps_error``:
outliers rejected from the track alone, SE(2)-aligned at the fixes); EKF-SLAM run with the
same association (the feature index).

The iSAM file ``isam/victoriaPark.txt`` (landmarks in the robot frame, ``se2_xy``; GTSAM has
no such factor in Python) is run by slamkit alone, against its batch optimum.
"""

from __future__ import annotations

import os
import sys
import time
from typing import Any

import numpy as np

from _common import Record, write_results
from slamkit.datasets import find_data_root, load_dataset
from slamkit.eval.gps import gps_error
from slamkit.io.posegraph import read_graph
from slamkit.optim import GraphData, OptimizerConfig, StoppingConfig, optimize
from slamkit.optim.fixed_lag import FixedLagConfig
from slamkit.optim.fixed_lag_landmarks import landmark_updates, smooth_landmark_fixed_lag
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.slam.landmark_graph import build_landmark_graph, solve_unfused, without_gps

WINDOWS = (10, 50)
ANCHOR_SIGMA = 1e-3
BATCH = OptimizerConfig(initialization="grow", stopping=StoppingConfig(relative_tolerance=1e-12))
"""The iSAM file's batch reference. Started from dead reckoning (the file's odometry chained,
or the graph's vertices) Gauss-Newton stops in a local minimum tens of metres from the
optimum (on the data set's graph: GPS RMSE 25.3 m against 4.7 m for iSAM2 over the same
factors); solves over growing prefixes reach the optimum."""


def _ms(t: np.ndarray) -> str:
    return f"{1e3 * np.median(t):.3f} | {1e3 * np.percentile(t, 95):.3f} | {t.sum():.1f}"


def _error(est: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    d = np.linalg.norm(est[:, :2] - ref[:, :2], axis=1)
    return float(np.sqrt(np.mean(d**2))), float(d.max())


def _run_gtsam(
    graph: GraphData, first: np.ndarray, window: int | None, lags: tuple[int, ...]
) -> tuple[dict[int, np.ndarray], np.ndarray, int]:
    """GTSAM's BatchFixedLagSmoother (``window``) or iSAM2 (``None``) over the stream (module
    docstring): online estimates ``{lag: (N, 3)}``, step times, landmark re-entries."""
    import gtsam

    steps = landmark_updates(graph)
    n = len(steps)
    isam = window is None
    lm = gtsam.LevenbergMarquardtParams()
    lm.setLinearSolverType("MULTIFRONTAL_QR")  # Cholesky: "indeterminate" near node 6026
    smoother: Any = (
        gtsam.ISAM2(gtsam.ISAM2Params()) if isam else gtsam.BatchFixedLagSmoother(float(window), lm)
    )
    X = [gtsam.symbol("x", k) for k in range(n)]
    lm_key: dict[int, int] = {}
    generation = 0
    reentries = 0
    online = {lag: np.zeros((n, 3)) for lag in lags}
    times = np.empty(n)
    current: Any = gtsam.Values()

    def pose(q: int) -> Any:
        if isam:
            return smoother.calculateEstimatePose2(X[q])
        return current.atPose2(X[q])

    def alive(key: int) -> bool:
        return smoother.calculateEstimate().exists(key) if isam else current.exists(key)

    for k, (pid, edges) in enumerate(steps):
        assert pid == k
        fg = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        stamps = gtsam.FixedLagSmootherKeyTimestampMap()
        if k == 0:
            x = gtsam.Pose2(*first)
            fg.add(
                gtsam.PriorFactorPose2(X[0], x, gtsam.noiseModel.Isotropic.Sigma(3, ANCHOR_SIGMA))
            )
        for es in edges:
            for i, j, z, info in zip(
                es.i.tolist(), es.j.tolist(), es.measurement, es.information, strict=True
            ):
                if es.kind == "se2":
                    x = pose(i).compose(gtsam.Pose2(*z))
                    noise = gtsam.noiseModel.Gaussian.Information(info)
                    fg.add(gtsam.BetweenFactorPose2(X[i], X[j], gtsam.Pose2(*z), noise))
        values.insert(X[k], x)
        stamps.insert((X[k], float(k)))
        for es in edges:
            if es.kind != "range_bearing":
                continue
            for j, z, info in zip(es.j.tolist(), es.measurement, es.information, strict=True):
                key = lm_key.get(j)
                if key is None or (not isam and not alive(key)):
                    reentries += key is not None
                    key = gtsam.symbol("l", generation)
                    generation += 1
                    lm_key[j] = key
                    a = x.theta() + z[1]
                    values.insert(
                        key, np.array([x.x() + z[0] * np.cos(a), x.y() + z[0] * np.sin(a)])
                    )
                perm = info[np.ix_([1, 0], [1, 0])]  # (range, bearing) → GTSAM's (bearing, range)
                fg.add(gtsam.BearingRangeFactor2D(
                    X[k], key, gtsam.Rot2(z[1]), float(z[0]),
                    gtsam.noiseModel.Gaussian.Information(perm),
                ))  # fmt: skip
                stamps.insert((key, float(k)))
        t0 = time.perf_counter()
        if isam:
            smoother.update(fg, values)
        else:
            smoother.update(fg, values, stamps)
        times[k] = time.perf_counter() - t0
        if not isam:
            current = smoother.calculateEstimate()
        for lag in lags:
            if k >= lag:
                p = pose(k - lag)
                online[lag][k - lag] = (p.x(), p.y(), p.theta())
    for lag in lags:
        for q in range(max(n - lag, 0), n):
            p = pose(q)
            online[lag][q] = (p.x(), p.y(), p.theta())
    return online, times, reentries


def _gps(ds: Any, times: np.ndarray, poses: np.ndarray) -> str:
    e = gps_error(times, poses, ds.truth.position_times, ds.truth.positions)
    return f"{e.rmse:.2f} | {e.median:.2f}"


def victoria_main(max_duration_s: float | None = None) -> str:
    """The tables of the module docstring (``max_duration_s``: the first seconds only, for a
    quick check; the results file is then not written)."""
    root = find_data_root()
    if root is None:
        return "bench_fixed_lag_victoria: skipped (no real data; set SLAMKIT_DATA)"
    loads = [os.getloadavg()]
    opts: dict[str, Any] = {"identities": True}
    if max_duration_s is not None:
        opts["max_duration_s"] = max_duration_s
    ds = load_dataset("victoria-park", options=opts, data_root=root)
    built = build_landmark_graph(ds)
    graph = without_gps(built)
    first = built.initial_poses[0]
    batch = solve_unfused(built)  # from solves over growing prefixes, as landmark-graph does
    t_batch = batch.seconds
    ref = batch.poses
    records: list[Record] = []
    rows = [
        "| window L | solver | median step [ms] | p95 step [ms] | total [s] | RMSE vs batch [m] "
        "| max vs batch [m] | landmark re-entries | GPS RMSE [m] | GPS median [m] |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    isam_online, isam_t, _ = _run_gtsam(graph, first, None, WINDOWS)
    for L in WINDOWS:
        res = smooth_landmark_fixed_lag(graph, FixedLagConfig(window=L), first_pose=first)
        bfl, bfl_t, bfl_re = _run_gtsam(graph, first, L, (L,))
        for label, poses, t, re in (
            ("slamkit LandmarkFixedLagSmoother", res.poses, res.step_seconds, res.reentries),
            ("GTSAM BatchFixedLagSmoother", bfl[L], bfl_t, bfl_re),
            (f"GTSAM iSAM2 (read {L} nodes later)", isam_online[L], isam_t, 0),
        ):
            e = _error(poses, ref)
            rows.append(
                f"| {L} | {label} | {_ms(t)} | {e[0]:.3f} | {e[1]:.3f} | {re} "
                f"| {_gps(ds, built.times, poses)} |"
            )
        for what, f in (("median", np.median), ("p95", lambda t: np.percentile(t, 95))):
            records.append(Record(f"victoria-park graph window {L}: {what} step",
                                  float(f(res.step_seconds)), "GTSAM BatchFixedLagSmoother",
                                  float(f(bfl_t))))  # fmt: skip
        loads.append(os.getloadavg())
    ekf_t = time.perf_counter()
    ekf = run("ekf-slam", ds, seed=0)
    ekf_t = time.perf_counter() - ekf_t
    g = evaluate(ekf, ds).metrics["gps"]
    rows.append(f"| — | batch (whole graph, growing prefixes) | — | — | {t_batch:.1f} | 0 | 0 | — "
                f"| {_gps(ds, built.times, ref)} |")  # fmt: skip
    rows.append(f"| — | EKF-SLAM, the same association | — | — | {ekf_t:.1f} | — | — | — "
                f"| {g['rmse']:.2f} | {g['median']:.2f} |")  # fmt: skip
    isam_rows = _isam_file_rows(root) if max_duration_s is None else []
    notes = "\n".join([
        f"Victoria Park's landmark graph (feature index as association, GPS left out): "
        f"{graph.pose_ids.shape[0]} nodes, {graph.landmark_ids.shape[0]} landmarks, "
        f"{graph.n_edges} edges. One run each. Load average (1, 5, 15 min) at the start and "
        "after each window: " + ", ".join(f"({a:.1f}, {b:.1f}, {c:.1f})" for a, b, c in loads)
        + ". EKF-SLAM's total is its whole run (pipeline.run).",
        "", *rows, "", *isam_rows,
    ])  # fmt: skip
    if max_duration_s is not None:
        return notes
    return write_results("fixed_lag_victoria", records, notes=notes)


def _isam_file_rows(root: Any) -> list[str]:
    """slamkit alone on the iSAM file, against its batch optimum."""
    graph = read_graph(root / "isam/victoriaPark.txt")
    ref = optimize(graph, BATCH)
    order = np.argsort(ref.pose_ids, kind="stable")
    rows = [
        "`isam/victoriaPark.txt` (slamkit alone; `slamkit optimize FILE --window L`):",
        "",
        "| window L | median step [ms] | p95 step [ms] | total [s] | RMSE vs batch [m] "
        "| max vs batch [m] | landmark re-entries | largest step system |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for L in WINDOWS:
        res = smooth_landmark_fixed_lag(graph, FixedLagConfig(window=L))
        e = _error(res.poses, ref.poses[order])
        rows.append(f"| {L} | {_ms(res.step_seconds)} | {e[0]:.3f} | {e[1]:.3f} "
                    f"| {res.reentries} | {res.max_unknowns} |")  # fmt: skip
    return rows


def main() -> str:
    return victoria_main()


if __name__ == "__main__":
    print(main() if len(sys.argv) < 2 else "usage: bench_fixed_lag_victoria.py")
