"""Victoria Park's GPS fused by EKF-SLAM, against EKF-SLAM without it and the landmark graph
with and without GPS (:mod:`bench_gps_fusion`'s default, the χ² gate) — every estimate scored
on the same held-out fixes.

The loader's ``gps_fuse`` puts every fix but each tenth (the 10th, 20th, …) into the stream;
the graph holds out the same tenth (``holdout_every = 10``). Scores
(:func:`slamkit.eval.gps_holdout.holdout_gps_error`) on the held-out fixes that the GPS track
alone does not reject: **aligned** (SE(2) fitted on the other fixes) and **direct** (none; only
meaningful for an estimate in the GPS frame). The readings carry the file's feature index
(``identities``), so all four see the same association. EKF-SLAM's lever arm: 0 (its
default) and the fused graph's estimate. Times: EKF-SLAM's whole run (``slamkit run``'s
pipeline); the graph's build, and each solve. Needs the real data (``SLAMKIT_DATA``).

    python benchmarks/bench_gps_ekf.py
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from _common import Record, write_results
from slamkit.datasets import find_data_root, load_dataset
from slamkit.eval.gps_holdout import holdout_gps_error
from slamkit.pipeline import run
from slamkit.slam.ekf_slam import EkfSlamConfig
from slamkit.slam.landmark_graph import (
    GpsFixes,
    LandmarkGraphConfig,
    build_landmark_graph,
    fused_start,
    solve_fused,
    solve_unfused,
)

HOLDOUT = 10
SIGMA = 1.0  # [m] the fixes' standard deviation per axis, the loader's default


def _row(label: str, seconds: float, s: Any, landmarks: int, extra: str) -> str:
    return (
        f"| {label} | {seconds:.1f} | {s.rmse:.2f} | {s.median:.2f} | {s.direct_rmse:.2f} | "
        f"{s.direct_median:.2f} | {landmarks} | {extra} |"
    )


def _ekf(ds: Any, lever: tuple[float, float]) -> tuple[Any, float, int]:
    t0 = time.perf_counter()
    res = run("ekf-slam", ds, config=EkfSlamConfig(gps_lever_arm=lever), seed=0)
    seconds = time.perf_counter() - t0
    lm = res.output.landmarks
    return res, seconds, -1 if lm is None else int(lm.landmarks.ids.shape[0])


def main() -> str:
    root = find_data_root()
    if root is None:
        return "bench_gps_ekf: skipped (no real data; set SLAMKIT_DATA)"
    plain = load_dataset("victoria-park", options={"identities": True}, data_root=root)
    fused_opts = {"identities": True, "gps_fuse": True, "gps_holdout_every": HOLDOUT}
    fusing = load_dataset("victoria-park", options=fused_opts, data_root=root)
    truth = plain.truth
    assert truth.position_times is not None and truth.positions is not None
    gps = GpsFixes(truth.position_times, truth.positions, sigma=SIGMA, holdout_every=HOLDOUT)
    load_before = os.getloadavg()[0]

    def score(res: Any, lever: Any) -> Any:
        return holdout_gps_error(
            res.times, res.poses, gps.times, gps.positions, gps.held_out, lever_arm=lever
        )

    t0 = time.perf_counter()
    built = build_landmark_graph(plain, gps=gps)
    build_s = time.perf_counter() - t0
    unfused = solve_unfused(built)
    start = fused_start(built, unfused)
    graph = solve_fused(built, *start, LandmarkGraphConfig())
    assert graph.lever_arm is not None and graph.weights is not None
    arm = (round(float(graph.lever_arm[0]), 2), round(float(graph.lever_arm[1]), 2))
    n_graph = int(unfused.landmark_ids.shape[0])
    rows = [
        _row("graph without GPS (solve)", unfused.seconds, score(unfused, (0.0, 0.0)),
             n_graph, "—"),
        _row("graph + GPS, χ² gate (solve)", graph.seconds, score(graph, graph.lever_arm),
             n_graph, f"{int((graph.weights < 0.1).sum())} of {int(built.fix_in_graph.sum())}"
             f" set aside; arm ({arm[0]:.2f}, {arm[1]:.2f}) estimated"),
    ]  # fmt: skip
    ekf_plain, plain_s, n_plain = _ekf(plain, (0.0, 0.0))
    rows.append(_row("EKF-SLAM without GPS", plain_s, score(ekf_plain, (0.0, 0.0)), n_plain, "—"))
    rows.append(
        _row("EKF-SLAM without GPS, scored with the graph's arm", plain_s,
             score(ekf_plain, arm), n_plain, "—")
    )  # fmt: skip
    records = [Record("EKF-SLAM without GPS", plain_s, "graph without GPS (solve)",
                      unfused.seconds)]  # fmt: skip
    for lever, label in (((0.0, 0.0), "arm 0 (default)"), (arm, "the graph's arm")):
        res, sec, n = _ekf(fusing, lever)
        d = res.output.diagnostics
        extra = (
            f"{d['gps_refused']} of {d['gps_fixes']} refused, {d['gps_aligning']} to move "
            f"into the GPS frame, {d['gps_fused']} fused"
        )
        rows.append(_row(f"EKF-SLAM + GPS, {label}", sec, score(res, lever), n, extra))
        records.append(
            Record(f"EKF-SLAM + GPS, {label}", sec, "graph + GPS, gate (solve)", graph.seconds)
        )
    table = "\n".join(
        [
            "| estimate | time [s] | held-out RMSE, aligned [m] | median, aligned [m] | "
            "direct RMSE [m] | direct median [m] | landmarks | GPS fixes |",
            "|---|---:|---:|---:|---:|---:|---:|---|",
            *rows,
        ]
    )
    s0 = score(ekf_plain, (0.0, 0.0))
    notes = (
        f"Victoria Park, whole run, readings with the file's feature index; "
        f"{gps.times.shape[0]} fixes, every {HOLDOUT}th held out ({int(gps.held_out.sum())}), "
        f"{int(s0.scored.sum())} held-out fixes scored (outliers by the GPS track alone left "
        f"out). Fix sigma {SIGMA:g} m. Graph built in {build_s:.1f} s (not in its rows' times); "
        f"EKF-SLAM times are whole runs. Direct scores of estimates outside the GPS frame mean "
        f"nothing. Load average (1 min) {load_before:.1f} before, {os.getloadavg()[0]:.1f} "
        f"after, on {os.cpu_count()} CPUs.\n\n{table}"
    )
    assert np.isfinite(s0.rmse)
    return write_results("gps_ekf", records, notes=notes)


if __name__ == "__main__":
    print(main())
