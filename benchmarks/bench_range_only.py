"""Range-only SLAM on CMU Plaza 1 with the beacons withheld: slamkit's ``range-only-slam``
(batch) against slamkit's EKF localisation *given* the surveyed beacons and against GTSAM
(iSAM2, and batch Levenberg-Marquardt) on the same graph, in one run.

The graph every SLAM column solves: slamkit's :class:`RangeOnlyProblem` of the run (a node at
every readings event, the odometry between nodes with its propagated covariance, a prior on
the first pose, one range factor per reading, σ_r = 0.5 m of the calibrated loader) and the
beacons started by slamkit's initialiser (``initialise_beacons``: the ranges along the
dead-reckoned path, the mirror kept until a cost gap of 25 rejects it). GTSAM gets the same
factors (``BetweenFactorPose2`` with ``noiseModel.Gaussian.Information`` of the same
information, ``PriorFactorPose2``, ``RangeFactor2D``) under the same Cauchy kernel (c = 1, on
every factor as in slamkit) and the same starts:

* **iSAM2** (default ``ISAM2Params``): one update per node in time order with that node's
  odometry factor and ranges; a beacon enters (at slamkit's start for it) at the node where
  slamkit's initialiser decided it, with its ranges buffered until then; a new pose starts
  at iSAM2's current estimate of the previous one composed with the odometry. This is the
  incremental counterpart of GTSAM's RangeISAM example (our code is written from its
  description, not copied).
* **iSAM2, its example's recipe**: every beacon starts at a random point (σ = 1 m about
  the first pose), one batch LM once 150 ranges are in, then an update every 25 ranges:
  what the mirror-aware starts are measured against; with plain Gaussian factors (the
  example's Tukey kernel on σ = 100 m ranges is all but quadratic) and with the Cauchy
  kernel.
* **LM batch**: ``LevenbergMarquardtOptimizer`` on the whole graph from slamkit's start
  (dead-reckoned path, beacon starts): the cross-check that both libraries reach the same
  optimum.

slamkit's online mode (``resolve_every_s = 30``: the run so far solved every 30 s of data,
warm-started) is scored twice: its final path and its online estimates.

Scores, at the node times (truth interpolated there): ATE after an SE(2) alignment of the
path and without; beacons against the surveyed ones after *the path's* alignment, after
their own alignment, and without. Times: slamkit's whole ``run`` (stream, starts, solve) and
its solve alone; GTSAM's time from building its factors to its estimate (the starts come
from slamkit and are not in GTSAM's time). A second table (``--no-kernels`` skips it) is the
measurement behind the default kernel: Plaza 1 and a simulated world with a share of the
ranges lengthened by U(2, 10) m.

Run: ``python benchmarks/bench_range_only.py`` (needs SLAMKIT_DATA; GTSAM optional: its
columns say "not installed" without it).
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from typing import Any

import numpy as np

from _common import RESULTS_DIR, Record, write_results
from slamkit.datasets import Dataset, find_data_root
from slamkit.datasets.plaza import load_plaza1
from slamkit.datasets.stream import LandmarkReadings
from slamkit.eval.trajectory import absolute_trajectory_error
from slamkit.geometry.pose2 import interpolate_poses
from slamkit.maps import LandmarkMap
from slamkit.optim.robust import RobustKernel
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.sim.scenarios import LandmarkScenarioConfig, landmark_dataset
from slamkit.slam.range_only import (
    RangeOnlyProblem,
    RangeOnlySlam,
    RangeOnlySlamConfig,
    initialise_beacons,
    odometry_information,
)

KERNEL = RobustKernel("cauchy", 1.0)
ONLINE_EVERY_S = 30.0  # the periodic solves of the online mode
OUTLIER_SHARES = (0.0, 0.05, 0.10, 0.20)
KERNELS = (("none", 1.0), ("huber", 3.0), ("cauchy", 1.0), ("cauchy", 3.0), ("dcs", 3.0))


# ------------------------------------------------------------------------------ scoring
def _scores(
    times: np.ndarray, poses: np.ndarray, beacons: LandmarkMap | None, ds: Dataset
) -> dict[str, float]:
    truth = ds.truth
    assert truth.poses is not None and truth.landmarks is not None
    ref = interpolate_poses(truth.times, truth.poses, times)
    ate = absolute_trajectory_error(poses, ref, align="se2")
    raw = absolute_trajectory_error(poses, ref, align="none")
    out = {"ate_aligned": ate.rmse, "ate_unaligned": raw.rmse, "heading_rmse": raw.heading_rmse}
    if beacons is not None:
        true = truth.landmarks
        idx = [int(np.flatnonzero(true.ids == b)[0]) for b in beacons.ids]
        want = true.positions[idx]
        by_path = ate.alignment.apply_to_points(beacons.positions) - want
        unaligned = beacons.positions - want
        own = absolute_trajectory_error(  # the beacons' own best rigid alignment
            np.column_stack([beacons.positions, np.zeros(len(idx))]),
            np.column_stack([want, np.zeros(len(idx))]),
        )
        out.update(
            beacons_path_aligned=float(np.sqrt(np.mean(np.sum(by_path**2, axis=1)))),
            beacons_own_aligned=own.rmse,
            beacons_unaligned=float(np.sqrt(np.mean(np.sum(unaligned**2, axis=1)))),
        )
    return out


# ------------------------------------------------------------------------------ GTSAM
def _gtsam_factors(problem: RangeOnlyProblem, gtsam: Any, kernel: bool = True) -> dict[str, Any]:
    """The graph's factors; ``kernel=False``: plain Gaussian noise models."""
    nm = gtsam.noiseModel

    def robust(base: Any) -> Any:
        if not kernel:
            return base
        return nm.Robust.Create(nm.mEstimator.Cauchy.Create(KERNEL.width), base)

    info = odometry_information(problem.odometry, problem.odometry_cov)
    between = [
        gtsam.BetweenFactorPose2(
            k, k + 1, gtsam.Pose2(*problem.odometry[k]), robust(nm.Gaussian.Information(info[k]))
        )
        for k in range(problem.odometry.shape[0])
    ]
    assert problem.prior_cov is not None
    prior = gtsam.PriorFactorPose2(
        0, gtsam.Pose2(*problem.node_poses[0]), robust(nm.Gaussian.Covariance(problem.prior_cov))
    )
    rnoise = robust(nm.Isotropic.Sigma(1, problem.sigma_range))
    ranges = [
        gtsam.RangeFactor2D(int(n), gtsam.symbol("L", int(b)), float(z), rnoise)
        for n, b, z in zip(problem.reading_node, problem.beacon_id, problem.ranges, strict=True)
    ]
    return {"between": between, "prior": prior, "ranges": ranges}


def _gtsam_isam2(problem: RangeOnlyProblem, starts: dict[int, Any], gtsam: Any) -> dict[str, Any]:
    t0 = time.perf_counter()
    f = _gtsam_factors(problem, gtsam)
    n = problem.node_poses.shape[0]
    node_of_start = {
        b: int(np.flatnonzero(problem.node_times == s.time)[0]) for b, s in starts.items()
    }
    by_node: dict[int, list[int]] = {}
    for k, node in enumerate(problem.reading_node):
        by_node.setdefault(int(node), []).append(k)
    waiting: dict[int, list[int]] = {b: [] for b in starts}
    isam = gtsam.ISAM2(gtsam.ISAM2Params())
    last = gtsam.Pose2(*problem.node_poses[0])
    for i in range(n):
        fg, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        if i == 0:
            fg.add(f["prior"])
            values.insert(0, last)
        else:
            fg.add(f["between"][i - 1])
            values.insert(i, last.compose(gtsam.Pose2(*problem.odometry[i - 1])))
        for k in by_node.get(i, []):
            b = int(problem.beacon_id[k])
            if b in waiting:
                waiting[b].append(k)
        for b, node in node_of_start.items():
            if node == i:
                values.insert(gtsam.symbol("L", b), gtsam.Point2(*starts[b].position))
        for b in list(waiting):
            if node_of_start[b] <= i:
                for k in waiting[b]:
                    fg.add(f["ranges"][k])
                waiting[b] = []
        isam.update(fg, values)
        last = isam.calculateEstimatePose2(i)
    est = isam.calculateEstimate()
    seconds = time.perf_counter() - t0
    return _gtsam_values(est, n, sorted(starts), gtsam) | {"seconds": seconds}


def _gtsam_example_recipe(problem: RangeOnlyProblem, gtsam: Any, kernel: bool) -> dict[str, Any]:
    """GTSAM's RangeISAM recipe on the same factors (``kernel=False``: without the Cauchy
    kernel; the example's own Tukey kernel on σ = 100 m ranges is all but quadratic): every
    beacon starts at a random point (σ = 1 m about the first pose, seed 0), one batch LM
    once 150 ranges are in, then an iSAM2 update whenever 25 more have come (the odometry in
    between chained on)."""
    t0 = time.perf_counter()
    f = _gtsam_factors(problem, gtsam, kernel)
    n = problem.node_poses.shape[0]
    rng = np.random.default_rng(0)
    ids = sorted(int(b) for b in np.unique(problem.beacon_id))
    by_node: dict[int, list[int]] = {}
    for k, node in enumerate(problem.reading_node):
        by_node.setdefault(int(node), []).append(k)
    isam = gtsam.ISAM2(gtsam.ISAM2Params())
    fg, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    fg.add(f["prior"])
    last = gtsam.Pose2(*problem.node_poses[0])
    values.insert(0, last)
    for b in ids:
        values.insert(
            gtsam.symbol("L", b), gtsam.Point2(*(problem.node_poses[0, :2] + rng.normal(size=2)))
        )
    seen, pending, started = 0, 0, False
    for i in range(1, n):
        fg.add(f["between"][i - 1])
        last = last.compose(gtsam.Pose2(*problem.odometry[i - 1]))
        values.insert(i, last)
        for k in by_node.get(i, []):
            fg.add(f["ranges"][k])
            seen, pending = seen + 1, pending + 1
        if (seen >= 150 and pending >= 25) or i == n - 1:
            if not started:
                values = gtsam.LevenbergMarquardtOptimizer(fg, values).optimize()
                started = True
            isam.update(fg, values)
            last = isam.calculateEstimatePose2(i)
            fg, values, pending = gtsam.NonlinearFactorGraph(), gtsam.Values(), 0
    est = isam.calculateEstimate()
    seconds = time.perf_counter() - t0
    return _gtsam_values(est, n, ids, gtsam) | {"seconds": seconds}


def _gtsam_batch(problem: RangeOnlyProblem, starts: dict[int, Any], gtsam: Any) -> dict[str, Any]:
    t0 = time.perf_counter()
    f = _gtsam_factors(problem, gtsam)
    fg, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    fg.add(f["prior"])
    for g in f["between"]:
        fg.add(g)
    for k, g in enumerate(f["ranges"]):
        if int(problem.beacon_id[k]) in starts:
            fg.add(g)
    for i, p in enumerate(problem.node_poses):
        values.insert(i, gtsam.Pose2(*p))
    for b, s in starts.items():
        values.insert(gtsam.symbol("L", b), gtsam.Point2(*s.position))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-6)
    params.setMaxIterations(100)
    est = gtsam.LevenbergMarquardtOptimizer(fg, values, params).optimize()
    seconds = time.perf_counter() - t0
    return _gtsam_values(est, problem.node_poses.shape[0], sorted(starts), gtsam) | {
        "seconds": seconds
    }


def _gtsam_values(est: Any, n: int, ids: list[int], gtsam: Any) -> dict[str, Any]:
    poses = np.array([[p.x(), p.y(), p.theta()] for p in map(est.atPose2, range(n))])
    xy = np.array([est.atPoint2(gtsam.symbol("L", b)) for b in ids]).reshape(-1, 2)
    return {"poses": poses, "beacons": LandmarkMap(xy, np.asarray(ids, dtype=np.int64))}


# ------------------------------------------------------------------------------ the runs
def _collect(ds: Dataset) -> RangeOnlySlam:
    est = RangeOnlySlam(ds, RangeOnlySlamConfig(), np.random.default_rng(0))
    for e in ds.events:
        est.handle(e)
    return est


def _plaza_table(ds: Dataset) -> tuple[list[Record], list[dict[str, Any]]]:
    t0 = time.perf_counter()
    ours = run("range-only-slam", ds, seed=0)
    t_ours = time.perf_counter() - t0
    problem = _collect(ds).problem
    nodes = problem.node_times
    d = ours.output.diagnostics
    assert ours.output.landmarks is not None
    rows: list[dict[str, Any]] = []

    def at_nodes(result: Any) -> np.ndarray:
        return interpolate_poses(result.times, result.poses, nodes)

    rows.append(
        {"method": "slamkit range-only-slam (batch, beacons unknown)", "seconds": t_ours,
         "solve_seconds": d["solve_seconds"] + d["init_seconds"]}
        | _scores(nodes, at_nodes(ours), ours.output.landmarks.landmarks, ds)
    )  # fmt: skip
    t0 = time.perf_counter()
    online = run("range-only-slam", ds, seed=0, config={"resolve_every_s": ONLINE_EVERY_S})
    t_online = time.perf_counter() - t0
    assert online.output.landmarks is not None and online.online_poses is not None
    solves = online.output.diagnostics["solves"]
    rows.append(
        {"method": f"slamkit range-only-slam, resolve_every_s = {ONLINE_EVERY_S:g} "
         f"({solves} solves): final", "seconds": t_online}
        | _scores(nodes, at_nodes(online), online.output.landmarks.landmarks, ds)
    )  # fmt: skip
    rows.append(
        {"method": "… the same run's online estimates", "seconds": t_online}
        | _scores(nodes, interpolate_poses(online.times, online.online_poses, nodes), None, ds)
    )
    for name in ("ekf-localization", "dead-reckoning"):
        t0 = time.perf_counter()
        res = run(name, ds, seed=0)
        label = "given the surveyed beacons" if name != "dead-reckoning" else "odometry only"
        rows.append(
            {"method": f"slamkit {name} ({label})", "seconds": time.perf_counter() - t0}
            | _scores(nodes, at_nodes(res), None, ds)
        )
    records = []
    try:
        import gtsam
    except ImportError:
        rows.append({"method": "GTSAM: not installed (pip install slamkit[bench])"})
        return records, rows
    starts = initialise_beacons(problem, KERNEL, RangeOnlySlamConfig().init_max_sigma)
    for kernel, what in ((False, "Gaussian factors"), (True, "the Cauchy kernel")):
        out = _gtsam_example_recipe(problem, gtsam, kernel)
        rows.append(
            {"method": "GTSAM iSAM2, its example's recipe (random beacon starts, batch LM "
             f"at 150 ranges, updates every 25), {what}", "seconds": out["seconds"]}
            | _scores(nodes, out["poses"], out["beacons"], ds)
        )  # fmt: skip
    for label, fn in (("iSAM2, incremental", _gtsam_isam2), ("LM batch", _gtsam_batch)):
        out = fn(problem, starts, gtsam)
        rows.append(
            {"method": f"GTSAM {label} (same graph and starts)", "seconds": out["seconds"]}
            | _scores(nodes, out["poses"], out["beacons"], ds)
        )
        if label == "LM batch":  # the solve alone against the solve alone
            case, mine = "Plaza 1: the batch solve (slamkit: starts + LM)", rows[0]["solve_seconds"]
        else:  # slamkit's whole run (stream, starts, solve) against iSAM2's whole stream
            case, mine = "Plaza 1: the whole run", t_ours
        records.append(Record(case, mine, f"GTSAM {label}", out["seconds"]))
        if label == "LM batch":
            ours_nodes = at_nodes(ours)
            rows[-1]["max_pose_difference_to_slamkit_m"] = float(
                np.max(np.hypot(*(out["poses"][:, :2] - ours_nodes[:, :2]).T))
            )
    return records, rows


def _world(seed: int) -> Dataset:
    cfg = LandmarkScenarioConfig(
        dt=0.2, speed=1.0, sigma_v=0.05, sigma_omega_deg=1.0, sensor="range",
        sigma_range=0.3, max_range=100.0, min_range=0.0, observe_every=5,
    )  # fmt: skip
    route = np.array([[40.0, 0.0], [40.0, 20.0], [0.0, 20.0], [0.0, 0.0]])
    world = LandmarkMap(
        np.array([[20.0, 6.0], [35.0, -8.0], [45.0, 25.0], [5.0, 30.0]]), np.arange(4)
    )
    return landmark_dataset(
        "sim", "sim", cfg, world, np.zeros(3), route, np.random.default_rng(seed)
    )


def _with_outliers(ds: Dataset, share: float, seed: int) -> tuple[Dataset, int]:
    rng = np.random.default_rng(seed)
    events, hits = [], 0
    for e in ds.events:
        if isinstance(e, LandmarkReadings):
            z = e.z.copy()
            hit = rng.random(z.shape[0]) < share
            z[hit, 0] += rng.uniform(2.0, 10.0, int(hit.sum()))
            hits += int(hit.sum())
            e = LandmarkReadings(e.t, z, e.ids)
        events.append(e)
    return dataclasses.replace(ds, events=tuple(events)), hits


def _kernel_table(plaza: Dataset) -> list[dict[str, Any]]:
    rows = []
    for name, base in (("Plaza 1", plaza), ("simulated world (seed 1)", _world(1))):
        for share in OUTLIER_SHARES:
            ds, hits = _with_outliers(base, share, seed=7)
            row: dict[str, Any] = {"data": name, "outlier_share": share, "outliers": hits}
            for kernel, width in KERNELS:
                res = run("range-only-slam", ds, seed=0,
                          config={"robust_kernel": kernel, "robust_width": width})  # fmt: skip
                m = evaluate(res, ds, max_dt=1e-3).metrics
                row[f"{kernel} {width:g}"] = (m["ate"]["rmse"], m["landmarks"]["rmse"])
            rows.append(row)
    return rows


def _markdown(rows: list[dict[str, Any]], kernels: list[dict[str, Any]]) -> str:
    def f(row: dict[str, Any], key: str) -> str:
        v = row.get(key)
        return "—" if v is None else f"{v:.3f}"

    lines = [
        "Plaza 1 (3,529 calibrated ranges to 4 beacons, 1.9 km, 32 min); scores at the "
        "{nodes} node times. Beacons: RMS error [m] after the path's alignment / their own "
        "alignment / none.",
        "",
        "| method | ATE aligned [m] | ATE unaligned [m] | heading RMS [rad] | beacons [m] "
        "| time [s] |",
        "|---|---:|---:|---:|---|---:|",
    ]
    for r in rows:
        if "ate_aligned" not in r:
            lines.append(f"| {r['method']} | | | | | |")
            continue
        b = (
            f"{f(r, 'beacons_path_aligned')} / {f(r, 'beacons_own_aligned')} / "
            f"{f(r, 'beacons_unaligned')}"
            if "beacons_unaligned" in r
            else "—"
        )
        solve = f" (solve {r['solve_seconds']:.2f})" if "solve_seconds" in r else ""
        lines.append(
            f"| {r['method']} | {f(r, 'ate_aligned')} | {f(r, 'ate_unaligned')} | "
            f"{f(r, 'heading_rmse')} | {b} | {r['seconds']:.2f}{solve} |"
        )
    if kernels:
        names = [f"{k} {w:g}" for k, w in KERNELS]
        lines += [
            "",
            "Robust kernels against outlier ranges (a share lengthened by U(2, 10) m): "
            "ATE aligned / beacon RMS after their own alignment [m].",
            "",
            "| data | share | outliers | " + " | ".join(names) + " |",
            "|---|---:|---:|" + "---|" * len(names),
        ]
        for r in kernels:
            cells = " | ".join(f"{r[n][0]:.3f} / {r[n][1]:.3f}" for n in names)
            lines.append(f"| {r['data']} | {r['outlier_share']:.2f} | {r['outliers']} | {cells} |")
    return "\n".join(lines)


def main() -> str:
    root = find_data_root()
    if root is None:
        raise SystemExit("data folder not found: set SLAMKIT_DATA")
    plaza = load_plaza1({}, seed=0, data_root=root)
    records, rows = _plaza_table(plaza)
    kernels = [] if "--no-kernels" in sys.argv else _kernel_table(plaza)
    n_nodes = _collect(plaza).problem.node_times.size
    notes = _markdown(rows, kernels).replace("{nodes}", f"{n_nodes:,}")
    RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    (RESULTS_DIR / "range_only_scores.json").write_text(
        json.dumps({"plaza1": rows, "kernels": kernels}, indent=2, default=float) + "\n",
        encoding="utf-8",
    )
    return write_results("range_only", records, notes=notes)


if __name__ == "__main__":
    print(main())
