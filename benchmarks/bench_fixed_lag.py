"""Fixed-lag smoothing of 2D pose graphs: slamkit's ``FixedLagSmoother`` against GTSAM's
``BatchFixedLagSmoother`` and iSAM2 on city10000 and Manhattan (M3500), the same poses and
edges fed in the same order, in one run: time per step and the error of each pose's online
estimate against slamkit's batch optimum.

Victoria Park, a pose-landmark graph, is in ``bench_fixed_lag_victoria.py`` (the landmark
smoother against the same two GTSAM solvers, and GPS RMSE beside EKF-SLAM), with its own
results (``results/fixed_lag_victoria.md``).

The stream: one step per pose in id order with the edges whose later end is that pose
(``slamkit.optim.updates.time_ordered_updates``). The first pose is the anchor (slamkit holds
it fixed at the file's vertex, the origin without one; GTSAM gets a ``PriorFactorPose2`` of
σ ``ANCHOR_SIGMA`` there). Every later pose's guess is the first edge of its step to a pose
the solver still holds, composed with *that solver's* current estimate of it (fetched
outside the timed call). Factors: ``BetweenFactorPose2`` with
``noiseModel.Gaussian.Information`` of the edge.

Windows: slamkit keeps ``L`` poses (a step solves over ``L + 1``, then the oldest leaves);
``BatchFixedLagSmoother(lag=L)`` with timestamp = step number keeps ``L + 1`` after a step
(solves over ``L + 2``). Each pose's **online estimate** is its estimate once ``L`` later
poses have arrived, for all three: slamkit's value as it leaves, GTSAM's estimate of pose
``k - L`` after the update of pose ``k``, iSAM2's likewise (iSAM2 keeps the whole graph: its
"lag" is only when the estimate is read); the last ``L`` poses take each solver's final
estimate. Both fixed-lag smoothers get the same edges: an edge whose older end left the
window (``i < j - L``; slamkit keeps edges to its fixed anchor, GTSAM drops those too once
the anchor is marginalised) is dropped. iSAM2 gets every edge.

Timed per step: slamkit's whole ``update()`` (validation, guess, Gauss-Newton, marginalisation;
``FixedLagResult.step_seconds``); GTSAM's ``smoother.update`` / ``isam.update``. slamkit runs
under the library's BLAS thread policy (``smooth_fixed_lag``); GTSAM with its own threads.
Error: translation RMSE and max of the online estimates against batch Gauss-Newton (relative
tolerance 1e-12) on the whole graph, both anchored at the first pose.

Run: ``python benchmarks/bench_fixed_lag.py`` or ``python benchmarks/run.py fixed_lag``.
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from _common import Record, write_results
from slamkit.datasets import find_data_root
from slamkit.io.posegraph import read_graph
from slamkit.optim import GraphData, OptimizerConfig, StoppingConfig, optimize
from slamkit.optim.fixed_lag import FixedLagConfig, smooth_fixed_lag
from slamkit.optim.updates import GraphUpdate, time_ordered_updates
from slamkit.runtime import blas_thread_counts

FILES = {"city10000": "posegraph2d/city10000.g2o", "manhattan": "posegraph2d/manhattan.g2o"}
QR = {"city10000": False, "manhattan": True}
"""GTSAM's factorisation per file: QR where its default Cholesky stops with an "indeterminate
linear system" (manhattan: iSAM2 near pose 695, the fixed-lag smoother near pose 357),
Cholesky elsewhere (QR makes iSAM2 seven times slower on city10000)."""
WINDOWS = (10, 50)
ANCHOR_SIGMA = 1e-3
"""σ of GTSAM's prior on the first pose: the only absolute information in the graph, so the
optimum holds that pose at its value whatever σ."""


def _ms(t: np.ndarray) -> str:
    return f"{1e3 * np.median(t):.3f} | {1e3 * np.percentile(t, 95):.3f} | {t.sum():.1f}"


def _error(est: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    d = np.linalg.norm(est[:, :2] - ref[:, :2], axis=1)
    return float(np.sqrt(np.mean(d**2))), float(d.max())


def _first_pose(updates: list[GraphUpdate]) -> np.ndarray:
    first = updates[0].initial_poses
    return np.zeros(3) if first is None else first[0]


def _edges_of(u: GraphUpdate) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
    return [
        (i, j, z, info)
        for es in u.edges
        for i, j, z, info in zip(
            es.i.tolist(), es.j.tolist(), es.measurement, es.information, strict=True
        )
    ]


def _guess(gtsam: Any, pid: int, edges: list, known: Any) -> Any:
    """The first edge tying ``pid`` to a pose ``known(other)`` returns a Pose2 for."""
    for i, j, z, _ in edges:
        if j == pid and (x := known(i)) is not None:
            return x.compose(gtsam.Pose2(*z))
        if i == pid and (x := known(j)) is not None:
            return x.compose(gtsam.Pose2(*z).inverse())
    raise AssertionError(f"pose {pid} has no edge to a pose the solver holds")


def _run_gtsam(
    updates: list[GraphUpdate], window: int | None, lags: tuple[int, ...], qr: bool
) -> tuple[dict[int, np.ndarray], np.ndarray, int]:
    """GTSAM's BatchFixedLagSmoother (``window``) or iSAM2 (``None``): the online estimates
    ``{lag: (N, 3)}`` (the last ``lag`` rows: the final estimate), the time of each update and
    the edges dropped."""
    import gtsam

    n = len(updates)
    ids = [int(u.pose_ids[0]) for u in updates]
    isam = window is None
    if isam:
        params = gtsam.ISAM2Params()
        if qr:
            params.setFactorization("QR")
        smoother: Any = gtsam.ISAM2(params)
    else:
        lm = gtsam.LevenbergMarquardtParams()
        if qr:
            lm.setLinearSolverType("MULTIFRONTAL_QR")
        smoother = gtsam.BatchFixedLagSmoother(float(window), lm)
    online = {lag: np.zeros((n, 3)) for lag in lags}
    times = np.empty(n)
    dropped = 0
    current: Any = gtsam.Values()

    def estimate(q: int) -> Any:
        if isam:
            return smoother.calculateEstimatePose2(q)
        return current.atPose2(q) if current.exists(q) else None

    for k, u in enumerate(updates):
        pid = ids[k]
        fg = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        edges = _edges_of(u)
        if window is not None:  # the same rule as slamkit's: the older end must be held
            held = set(ids[max(k - window, 0) : k])
            keep = [(i if j == pid else j) in held for i, j, _, _ in edges]
            dropped += keep.count(False)
            edges = [e for e, ok in zip(edges, keep, strict=True) if ok]
        if k == 0:
            x0 = gtsam.Pose2(*_first_pose(updates))
            anchor = gtsam.noiseModel.Isotropic.Sigma(3, ANCHOR_SIGMA)
            fg.add(gtsam.PriorFactorPose2(pid, x0, anchor))
            values.insert(pid, x0)
        else:
            values.insert(pid, _guess(gtsam, pid, edges, estimate))
        for i, j, z, info in edges:
            noise = gtsam.noiseModel.Gaussian.Information(info)
            fg.add(gtsam.BetweenFactorPose2(i, j, gtsam.Pose2(*z), noise))
        if isam:
            t0 = time.perf_counter()
            smoother.update(fg, values)
            times[k] = time.perf_counter() - t0
        else:
            stamps = gtsam.FixedLagSmootherKeyTimestampMap()
            stamps.insert((pid, float(k)))
            t0 = time.perf_counter()
            smoother.update(fg, values, stamps)
            times[k] = time.perf_counter() - t0
            current = smoother.calculateEstimate()
        for lag in lags:
            if k >= lag:
                p = estimate(ids[k - lag])
                online[lag][k - lag] = (p.x(), p.y(), p.theta())
    for lag in lags:
        for q in range(max(n - lag, 0), n):
            p = estimate(ids[q])
            online[lag][q] = (p.x(), p.y(), p.theta())
    return online, times, dropped


def _file_rows(
    name: str, graph: GraphData, records: list[Record], flat: list[str]
) -> tuple[list[str], str]:
    """The table rows of one file (records and the constant-cost lines appended)."""
    import gtsam  # noqa: F401  (the peer must be present: the comparison is the point)

    updates = time_ordered_updates(graph)
    t0 = time.perf_counter()
    batch = optimize(
        graph, OptimizerConfig(solver="gn", stopping=StoppingConfig(relative_tolerance=1e-12))
    )
    t_batch = time.perf_counter() - t0
    ref = batch.poses  # rows: the file's vertex order, else sorted ids = step order
    order = np.argsort(batch.pose_ids, kind="stable")
    ref = ref[order]
    rows = []
    isam_online, isam_t, _ = _run_gtsam(updates, None, WINDOWS, QR[name])
    for L in WINDOWS:
        res = smooth_fixed_lag(graph, FixedLagConfig(window=L))
        assert np.array_equal(res.pose_ids, batch.pose_ids[order])
        ours_t = res.step_seconds
        bfl_online, bfl_t, bfl_dropped = _run_gtsam(updates, L, (L,), QR[name])
        e_ours, e_bfl, e_isam = (
            _error(res.poses, ref),
            _error(bfl_online[L], ref),
            _error(isam_online[L], ref),
        )
        rows.append(
            f"| {name} | {L} | slamkit FixedLagSmoother | {_ms(ours_t)} | {e_ours[0]:.3f} "
            f"| {e_ours[1]:.3f} | {res.dropped_edges} |"
        )
        rows.append(
            f"| {name} | {L} | GTSAM BatchFixedLagSmoother | {_ms(bfl_t)} | {e_bfl[0]:.3f} "
            f"| {e_bfl[1]:.3f} | {bfl_dropped} |"
        )
        rows.append(
            f"| {name} | {L} | GTSAM iSAM2 (read {L} poses later) | {_ms(isam_t)} "
            f"| {e_isam[0]:.3f} | {e_isam[1]:.3f} | 0 |"
        )
        q = len(updates) // 10
        flat.append(
            f"{name}, L = {L}: slamkit's median step over the first tenth of the run "
            f"{1e3 * np.median(ours_t[:q]):.3f} ms, over the last tenth "
            f"{1e3 * np.median(ours_t[-q:]):.3f} ms"
        )
        for what, f in (("median", np.median), ("p95", lambda t: np.percentile(t, 95))):
            records.append(
                Record(
                    f"{name} window {L}: {what} step",
                    float(f(ours_t)),
                    "GTSAM BatchFixedLagSmoother",
                    float(f(bfl_t)),
                )
            )
        records.append(
            Record(
                f"{name} window {L}: median step",
                float(np.median(ours_t)),
                "GTSAM iSAM2",
                float(np.median(isam_t)),
            )
        )
    last = _error(isam_online[WINDOWS[0]][-1:], ref[-1:])[1]
    check = (
        f"{name}: {len(updates)} poses, {graph.n_edges} edges; batch GN {t_batch:.2f} s, "
        f"χ² {batch.chi2:.6g}; iSAM2's final estimate of the last pose is {last:.3g} m from "
        "batch's"
    )
    return rows, check


def main() -> str:
    root = find_data_root()
    if root is None:
        raise SystemExit("data folder not found: set SLAMKIT_DATA")
    try:
        import gtsam  # noqa: F401
    except ImportError:
        raise SystemExit("GTSAM is not installed (pip install slamkit[bench]): no peer") from None
    try:
        import gtsam_unstable  # noqa: F401

        unstable = "gtsam_unstable imports; BatchFixedLagSmoother is taken from gtsam (4.3)"
    except ImportError:
        unstable = (
            "gtsam_unstable does not import, but GTSAM 4.3's own module has BatchFixedLagSmoother"
        )
    records: list[Record] = []
    rows = [
        "| file | window L | solver | median step [ms] | p95 step [ms] | total [s] "
        "| RMSE vs batch [m] | max vs batch [m] | edges dropped |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    checks: list[str] = []
    flat: list[str] = []
    loads = [os.getloadavg()]
    for name, rel in FILES.items():
        file_rows, check = _file_rows(name, read_graph(root / rel), records, flat)
        rows.extend(file_rows)
        checks.append(check)
        loads.append(os.getloadavg())
    notes = "\n".join(
        [
            f"One run of each solver per file and window; {unstable}. GTSAM's factorisation: "
            f"QR on {', '.join(k for k, v in QR.items() if v)}, Cholesky on the others. BLAS "
            f"threads: {blas_thread_counts()} (slamkit's one-thread policy applies inside "
            "smooth_fixed_lag).",
            "Load average (1, 5, 15 min) at the start and after each file: "
            + ", ".join(f"({a:.1f}, {b:.1f}, {c:.1f})" for a, b, c in loads)
            + ".",
            "",
            *rows,
            "",
            *[f"* {c}" for c in checks],
            *[f"* {c}" for c in flat],
        ]
    )
    return write_results("fixed_lag", records, notes=notes)


if __name__ == "__main__":
    print(main())
