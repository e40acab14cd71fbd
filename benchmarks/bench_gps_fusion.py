"""Victoria Park with its GPS fused into the landmark graph, against the graph without GPS and
EKF-SLAM on the same data and the same association — scored on fixes none of them was given.

Every tenth fix (the 10th, 20th, …) is held out of the fused graph; every estimate is scored
on the held-out fixes that the GPS track alone does not reject as outliers
(:func:`slamkit.eval.gps_holdout.holdout_gps_error`): **aligned** (SE(2) fitted on the other
fixes, then applied; needed for the estimates that live in their own frame) and, for the fused
graph, **direct** (no alignment: it lives in the GPS frame). The readings carry the file's
feature index (``identities``), so the graph and the EKF-SLAM run see the same association.

Rows: the unfused graph; the fused graph with each way of weighting the fixes (none, the four
robust kernels of ``slamkit.optim.robust`` at their default widths, and the χ² gate at the
99 % quantile of χ²(2)); each weighting again with multipath-like bursts added to the fixes;
the fused graph across artificial dropouts (every fix inside 8 windows held out); the fused
graph with other fix sigmas (gate); EKF-SLAM (the pipeline run, as ``slamkit run
ekf-slam``). Times: the graph solves (building and the shared unfused solve reported
apart), EKF-SLAM's whole run. GTSAM (when installed) solves the fused graph at the gate's
final weights from the same start: its GPS factors are for ``Pose3``/navigation states, so
the planar fix with a lever arm is a ``CustomFactor`` with slamkit's Jacobians; the answers
are compared. Needs the real data (``SLAMKIT_DATA``).

    python benchmarks/bench_gps_fusion.py
"""

from __future__ import annotations

import importlib.util
import os
import time
from dataclasses import replace
from typing import Any

import numpy as np

from _common import Record, write_results
from slamkit.datasets import find_data_root, load_dataset
from slamkit.eval.gps_holdout import holdout_gps_error
from slamkit.optim import OptimizerConfig, optimize
from slamkit.optim.data import EdgeSet, GraphData
from slamkit.optim.gps import GpsWeighting, gps_error
from slamkit.optim.objectives import g2o_chi2
from slamkit.optim.robust import DEFAULT_WIDTHS
from slamkit.pipeline import run
from slamkit.slam.landmark_graph import (
    GpsFixes,
    LandmarkGraphConfig,
    build_landmark_graph,
    fused_start,
    solve_fused,
    solve_unfused,
)

HOLDOUT = 10
SIGMA = 1.0  # [m] the fixes' standard deviation per axis (the default of the comparison)
WEIGHTINGS: tuple[tuple[str, float], ...] = (
    ("none", 1.0),
    ("huber", DEFAULT_WIDTHS["huber"]),
    ("cauchy", DEFAULT_WIDTHS["cauchy"]),
    ("geman_mcclure", DEFAULT_WIDTHS["geman_mcclure"]),
    ("dcs", DEFAULT_WIDTHS["dcs"]),
    ("gate", 9.21),
)
SIGMAS = (0.5, 2.0, 4.0)
BURSTS = 30  # multipath-like bursts added in the robustness experiment
BURST_SECONDS = 5.0
DROPOUTS = (30.0, 60.0, 120.0)  # [s] lengths of the artificial dropouts


NO_GPS = "— | — | — | —"


def _row(label: str, seconds: float, score: Any, landmarks: int, extra: str = NO_GPS) -> str:
    d = score.as_dict()
    return (
        f"| {label} | {seconds:.2f} | {d['rmse']:.2f} | {d['median']:.2f} | {extra} | {landmarks} |"
    )


def _injected(ds: Any, gps: GpsFixes, start: Any) -> list[str]:
    """Each weighting with multipath-like bursts added to the fused fixes (seeded): 30 bursts
    of 5 s, each moving every fused fix in it by one offset of 5-20 m. Scored on the clean
    held-out fixes, all of them and those within 1 s of a burst."""
    rng = np.random.default_rng(0)
    t = gps.times
    xy = gps.positions.copy()
    bad = np.zeros(t.shape[0], dtype=bool)
    near = np.zeros(t.shape[0], dtype=bool)
    for s0 in rng.choice(t.shape[0], BURSTS, replace=False):
        inside = (t >= t[s0]) & (t < t[s0] + BURST_SECONDS) & ~gps.held_out
        ang, dist = rng.uniform(0.0, 2.0 * np.pi), rng.uniform(5.0, 20.0)
        xy[inside] += dist * np.array([np.cos(ang), np.sin(ang)])
        bad |= inside
        near |= (t >= t[s0] - 1.0) & (t < t[s0] + BURST_SECONDS + 1.0)
    dirty = GpsFixes(t, xy, sigma=SIGMA, holdout_every=HOLDOUT)
    built = build_landmark_graph(ds, gps=dirty)
    fused_bad = np.isin(np.flatnonzero(built.fix_in_graph), np.flatnonzero(bad))
    rows = []
    for name, width in WEIGHTINGS:
        cfg = LandmarkGraphConfig(weighting=GpsWeighting(name, width))  # type: ignore[arg-type]
        sol = solve_fused(built, *start, cfg)
        assert sol.lever_arm is not None and sol.weights is not None
        s = holdout_gps_error(sol.times, sol.poses, t, gps.positions, gps.held_out, sol.lever_arm)
        by_burst = near[s.scored]
        near_rmse = float(np.sqrt(np.mean(s.direct_errors[by_burst] ** 2)))
        caught = float(np.mean(sol.weights[fused_bad] < 0.1))
        rows.append(
            f"| {name} ({width:g}) | {s.rmse:.2f} | {s.median:.2f} | {near_rmse:.2f} "
            f"({int(by_burst.sum())}) | ({sol.lever_arm[0]:.2f}, {sol.lever_arm[1]:.2f}) | "
            f"{caught:.1%} of {int(fused_bad.sum())} | {sol.rounds} | {sol.seconds:.2f} |"
        )
    return rows


def _peer(built: Any, weights: np.ndarray, start: Any, records: list[Record]) -> str:
    """GTSAM on the fused graph at the gate's final weights, from the same start as slamkit's
    solve of that graph; a record of both times and a note of how the answers agree."""
    if importlib.util.find_spec("gtsam") is None:
        return "GTSAM is not installed: the peer solve is skipped (pip install 'slamkit[bench]')."
    graph = _inlier_graph(built, weights)
    t0 = time.perf_counter()
    ours = optimize(
        graph,
        OptimizerConfig(initialization="vertices"),
        initial_poses=start[0],
        initial_landmarks=start[1],
    )
    t_ours = time.perf_counter() - t0
    t_peer, (poses, landmarks) = _gtsam_peer(graph, *start)
    records.append(Record("fused graph at the gate's weights, LM", t_ours, "GTSAM LM", t_peer))
    chi2_peer = g2o_chi2(graph, poses, landmarks)
    d_pose = float(np.abs(poses[:, :2] - ours.poses[:, :2]).max())
    d_lm = float(np.abs(landmarks - ours.landmarks).max())
    return (
        f"GTSAM cross-check on the fused graph at the gate's final weights "
        f"({int((weights > 0.5).sum())} fixes): slamkit χ² {ours.cost:.2f} in {t_ours:.2f} s, "
        f"GTSAM's answer χ² {chi2_peer:.2f} (g2o's SE(2) error; GTSAM minimises its Logmap "
        f"error, a slightly different objective) in {t_peer:.1f} s, largest difference "
        f"{d_pose * 1000:.1f} mm in a position, {d_lm * 1000:.1f} mm in a landmark or the lever "
        f"arm. GTSAM's time is mostly the Python callbacks of its CustomFactor GPS factors "
        f"(it has no planar GPS factor with a lever arm): a check of the answer, not a race."
    )


def _inlier_graph(built: Any, weights: np.ndarray) -> GraphData:
    """The fused graph with the fixes of weight 0 removed and the others at weight 1."""
    g = built.graph
    edges = []
    for e in g.edges:
        if e.kind == "gps":
            keep = weights > 0.5
            e = EdgeSet(e.kind, e.i[keep], e.j[keep], e.measurement[keep],
                        e.information[keep], e.lines[keep])  # fmt: skip
        edges.append(e)
    return replace(g, edges=tuple(edges))


def _gtsam_peer(graph: GraphData, poses: np.ndarray, landmarks: np.ndarray) -> tuple[float, Any]:
    """GTSAM's Levenberg-Marquardt on ``graph`` from the same start: odometry as
    ``BetweenFactorPose2``, readings as ``BearingRangeFactor2D``, each fix as a
    ``CustomFactor`` on the pose and the lever arm (a ``Point2``) with the Jacobians of
    ``slamkit.optim.gps``. Returns the solve time and the (poses, landmarks) reached."""
    import gtsam

    def x(i: int) -> int:
        return int(gtsam.symbol("x", int(i)))

    def lm(j: int) -> int:
        return int(gtsam.symbol("l", int(j)))

    fg = gtsam.NonlinearFactorGraph()
    for e in graph.edges:
        for k in range(len(e)):
            if e.kind == "se2":
                noise = gtsam.noiseModel.Gaussian.Information(e.information[k])
                fg.add(gtsam.BetweenFactorPose2(x(e.i[k]), x(e.j[k]),
                                                gtsam.Pose2(*e.measurement[k]), noise))  # fmt: skip
            elif e.kind == "range_bearing":
                info = e.information[k]  # diagonal (range, bearing); GTSAM orders bearing first
                sig = np.array([1.0 / np.sqrt(info[1, 1]), 1.0 / np.sqrt(info[0, 0])])
                fg.add(gtsam.BearingRangeFactor2D(
                    x(e.i[k]), lm(e.j[k]), gtsam.Rot2(e.measurement[k, 1]),
                    float(e.measurement[k, 0]), gtsam.noiseModel.Diagonal.Sigmas(sig)))  # fmt: skip
            elif e.kind == "gps":
                z = e.measurement[k].copy()
                noise = gtsam.noiseModel.Gaussian.Information(e.information[k])
                fg.add(gtsam.CustomFactor(noise, [x(e.i[k]), lm(e.j[k])], _gps_error_fn(z)))
    values = gtsam.Values()
    for pid, p in zip(graph.pose_ids, poses, strict=True):
        values.insert(x(pid), gtsam.Pose2(*p))
    for lid, q in zip(graph.landmark_ids, landmarks, strict=True):
        values.insert(lm(lid), np.asarray(q, dtype=float))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-9)
    params.setAbsoluteErrorTol(1e-9)
    t0 = time.perf_counter()
    result = gtsam.LevenbergMarquardtOptimizer(fg, values, params).optimize()
    seconds = time.perf_counter() - t0
    out_p = np.array([[*result.atPose2(x(i)).translation(), result.atPose2(x(i)).theta()]
                      for i in graph.pose_ids])  # fmt: skip
    out_l = np.array([result.atPoint2(lm(j)) for j in graph.landmark_ids])
    return seconds, (out_p, out_l)


def _gps_error_fn(z: np.ndarray) -> Any:
    """The GPS error ``t + R o - z`` of one fix for ``gtsam.CustomFactor``."""

    def error(this: Any, values: Any, jacobians: Any) -> np.ndarray:
        pose = values.atPose2(this.keys()[0])
        o = values.atPoint2(this.keys()[1])
        xi = np.array([[pose.x(), pose.y(), pose.theta()]])
        e, Ji, Jo = gps_error(xi, o[None, :], z[None, :])
        if jacobians is not None:
            jacobians[0] = Ji[0]
            jacobians[1] = Jo[0]
        return e[0]

    return error


def _dropouts(ds: Any, gps: GpsFixes) -> list[str]:
    """Artificial dropouts: 8 windows of L seconds (seeded starts) whose fixes are all held
    out; the graph is fused with the rest and scored on the fixes inside the windows."""
    rng = np.random.default_rng(0)
    t, xy = gps.times, gps.positions
    rows = []
    for length in DROPOUTS:
        hold = np.zeros(t.shape[0], dtype=bool)
        for s0 in rng.uniform(t[0], t[-1] - length, 8):
            hold |= (t >= s0) & (t < s0 + length)
        built = build_landmark_graph(ds, gps=GpsFixes(t[~hold], xy[~hold], sigma=SIGMA))
        unfused = solve_unfused(built)
        sol = solve_fused(built, *fused_start(built, unfused))
        assert sol.lever_arm is not None
        s = holdout_gps_error(sol.times, sol.poses, t, xy, hold, sol.lever_arm)
        su = holdout_gps_error(unfused.times, unfused.poses, t, xy, hold, sol.lever_arm)
        rows.append(
            f"| 8 × {length:g} s | {int(s.scored.sum())} | {s.direct_rmse:.2f} | "
            f"{s.direct_median:.2f} | {s.rmse:.2f} | {su.rmse:.2f} |"
        )
    return rows


def main() -> str:
    root = find_data_root()
    if root is None:
        return "bench_gps_fusion: skipped (no real data; set SLAMKIT_DATA)"
    ds = load_dataset("victoria-park", options={"identities": True}, data_root=root)
    truth = ds.truth
    assert truth.position_times is not None and truth.positions is not None
    gps = GpsFixes(truth.position_times, truth.positions, sigma=SIGMA, holdout_every=HOLDOUT)
    load_before = os.getloadavg()[0]
    rows: list[str] = []
    records: list[Record] = []
    results: dict[str, Any] = {}

    t0 = time.perf_counter()
    built = build_landmark_graph(ds, gps=gps)
    build_s = time.perf_counter() - t0
    unfused = solve_unfused(built)
    start = fused_start(built, unfused)

    def score(sol: Any, lever: Any) -> Any:
        return holdout_gps_error(
            sol.times, sol.poses, gps.times, gps.positions, gps.held_out, lever_arm=lever
        )

    n_map = int(unfused.landmark_ids.shape[0])
    s_un = score(unfused, (0.0, 0.0))
    rows.append(_row("graph without GPS", unfused.seconds, s_un, n_map))
    fused_lever = None
    gate_s = float("nan")
    gate_weights = np.zeros(0)
    for name, width in WEIGHTINGS:
        cfg = LandmarkGraphConfig(weighting=GpsWeighting(name, width))  # type: ignore[arg-type]
        sol = solve_fused(built, *start, cfg)
        assert sol.lever_arm is not None and sol.weights is not None
        s = score(sol, sol.lever_arm)
        label = f"graph + GPS, {name}" + ("" if name == "none" else f" ({width:g})")
        zero = int((sol.weights < 0.1).sum())
        extra = (
            f"{s.direct_rmse:.2f} / {s.direct_median:.2f} | ({sol.lever_arm[0]:.2f}, "
            f"{sol.lever_arm[1]:.2f}) | {sol.rounds} | {zero}"
        )
        rows.append(_row(label, sol.seconds, s, int(sol.landmark_ids.shape[0]), extra))
        results[name] = s
        if name == "gate":
            fused_lever = sol.lever_arm
            gate_weights = sol.weights
            gate_s = sol.seconds
            records.append(Record("fused (gate)", gate_s, "graph without GPS", unfused.seconds))
    peer_note = _peer(built, gate_weights, start, records)
    inject_rows = _injected(ds, gps, start)
    drop_rows = _dropouts(ds, gps)
    gaps = np.diff(gps.times)
    sigma_rows = []
    for sigma in SIGMAS:
        g2 = GpsFixes(gps.times, gps.positions, sigma=sigma, holdout_every=HOLDOUT)
        b2 = build_landmark_graph(ds, gps=g2)
        sol = solve_fused(b2, *start, LandmarkGraphConfig())
        assert sol.lever_arm is not None
        s = score(sol, sol.lever_arm)
        sigma_rows.append(
            f"| {sigma:g} | {s.rmse:.2f} | {s.median:.2f} | {s.direct_rmse:.2f} | "
            f"{sol.seconds:.2f} |"
        )
    # The unfused graph scored with the fused lever arm: how much of its error is the arm.
    s_arm = score(unfused, fused_lever)
    rows.append(_row("graph without GPS, fused lever arm", unfused.seconds, s_arm, n_map))

    wall = time.perf_counter()
    ekf = run("ekf-slam", ds, seed=0)
    wall = time.perf_counter() - wall
    s_ekf = score(ekf, (0.0, 0.0))
    n_ekf = -1 if ekf.output.landmarks is None else int(ekf.output.landmarks.landmarks.ids.shape[0])
    rows.append(_row("EKF-SLAM, the file's association", wall, s_ekf, n_ekf))
    s_ekf_arm = score(ekf, fused_lever)
    rows.append(_row("EKF-SLAM, fused lever arm", wall, s_ekf_arm, n_ekf))
    records.append(Record("fused (gate)", gate_s, "EKF-SLAM, whole run", wall))

    head = (
        "| estimate | time [s] | held-out RMSE, aligned [m] | median, aligned [m] | "
        "direct RMSE / median [m] | lever arm [m] | rounds | fixes weighted < 0.1 | landmarks |"
    )
    table = "\n".join(
        [
            head,
            "|---|---:|---:|---:|---:|---|---:|---:|---:|",
            *rows,
        ]
    )
    sig_table = "\n".join(
        [
            "| fix sigma [m] (gate) | held-out RMSE, aligned [m] | median [m] | "
            "direct RMSE [m] | solve [s] |",
            "|---:|---:|---:|---:|---:|",
            *sigma_rows,
        ]
    )
    inj_table = "\n".join(
        [
            "| weighting, with bursts | held-out RMSE, aligned [m] | median [m] | "
            "direct RMSE near bursts [m] (fixes) | lever arm [m] | moved fixes weighted < 0.1 "
            "| rounds | solve [s] |",
            "|---|---:|---:|---:|---|---:|---:|---:|",
            *inject_rows,
        ]
    )
    drop_table = "\n".join(
        [
            "| dropouts (gate) | fixes inside, scored | direct RMSE [m] | direct median [m] | "
            "aligned RMSE [m] | graph without GPS, aligned, fused arm [m] |",
            "|---|---:|---:|---:|---:|---:|",
            *drop_rows,
        ]
    )
    notes = (
        f"Victoria Park, whole run: {built.times.shape[0]} pose nodes, "
        f"{n_map} trees, {len(built.graph.edges[1])} readings with the file's feature index, "
        f"{gps.times.shape[0]} fixes, {int(built.fix_in_graph.sum())} fused, "
        f"{int(s_un.scored.sum())} held-out fixes scored (every {HOLDOUT}th, outliers by the "
        f"GPS track alone left out). Graph built in {build_s:.2f} s; fused solves start from "
        f"the unfused solution moved into the GPS frame. Fix sigma {SIGMA:g} m unless stated. "
        f"Load average (1 min) {load_before:.1f} before, {os.getloadavg()[0]:.1f} after, on "
        f"{os.cpu_count()} CPUs. The recorded GPS has {int((gaps > 5).sum())} gaps over 5 s "
        f"(longest {gaps.max():.0f} s, {gaps[gaps > 5].sum():.0f} s in all).\n\n{table}\n\n"
        f"{peer_note}\n\n{inj_table}\n\n{drop_table}\n\n{sig_table}"
    )
    return write_results("gps_fusion", records, notes=notes)


if __name__ == "__main__":
    print(main())
