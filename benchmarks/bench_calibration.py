"""Calibration recovery on simulated runs: injected wheel-radius and wheel-base errors and a
laser mounted 5 cm off the robot's centre, recovered by :func:`slamkit.calibration.calibrate`.

Each run is the rooms tour (``rooms-laser``, six laps, a laser of 1 cm range noise) with its
scans cast again from ``robot ⊕ (0.05, 0, 0)`` while the data set states the laser at the
centre (:func:`slamkit.sim.remount_laser`), and its odometry rebuilt under the stated error
model (:func:`slamkit.sim.corrupt_odometry`) with chosen systematic errors: the corpus's
typical random noise, or the same with a third of its turn noise (``k_rot`` 0.01), with and
without glitches. Five seeds per case. (``corrupt_odometry`` scales the unsigned ``rot1 = ±π``
of the simulated robot's small steps back when the turn scale is not 1, a heading jump the
calibration must trim: ``tests/sim/test_odometry_errors_backward.py``.)

No peer library implements this calibration. The comparison is with the *oracle*: the same
fits on the true laser motions (the pairs' matches replaced by the truth, the matcher's
covariance by 1 µm / 1 µrad), which shows how much of the error is the odometry's own noise
and how much the scan matching adds. The records time the whole calibration (matching and
fits) against the oracle's fits alone.

Run: ``python benchmarks/bench_calibration.py`` or ``python benchmarks/run.py calibration``.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import replace
from typing import Any

import numpy as np

from _common import RESULTS_DIR, Record, write_results
from slamkit.calibration import (
    CalibrationSettings,
    calibrate_pairs,
    odometry_at_scans,
    scan_pairs,
)
from slamkit.datasets import load_dataset
from slamkit.geometry.pose2 import between, compose, interpolate_poses
from slamkit.sim import OdometryErrorModel, corrupt_odometry, remount_laser

SEEDS = range(5)
MOUNTING = (0.05, 0.0, 0.0)
CASES: list[tuple[str, OdometryErrorModel]] = [
    ("radius 2 %, typical noise", OdometryErrorModel(wheel_radius_error=0.02,
                                                     wheel_base_error=0.0)),
    ("base 3 %, typical noise", OdometryErrorModel(wheel_radius_error=0.0,
                                                   wheel_base_error=0.03)),
    ("radius 2 %, k_rot 0.01", OdometryErrorModel(k_rot=0.01, wheel_radius_error=0.02,
                                                   wheel_base_error=0.0)),
    ("base 3 %, k_rot 0.01", OdometryErrorModel(k_rot=0.01, wheel_radius_error=0.0,
                                                 wheel_base_error=0.03)),
    ("both, k_rot 0.01", OdometryErrorModel(k_rot=0.01, wheel_radius_error=0.02,
                                             wheel_base_error=0.03)),
]  # fmt: skip
GLITCHES = {"both, k_rot 0.01, glitches"}


def _oracle(data: Any, pairs: Any) -> Any:
    """``pairs`` with the true laser motions and a negligible matcher covariance."""
    times, _, _ = odometry_at_scans(data)
    laser = compose(interpolate_poses(data.truth.times, data.truth.poses, times), MOUNTING)
    true = between(laser[pairs.first], laser[pairs.last])
    cov = np.broadcast_to(np.diag([1e-12, 1e-12, 1e-12]), pairs.cov.shape).copy()
    return replace(pairs, T_laser=true, cov=cov)


def _row(result: Any, radius: float, base: float) -> dict[str, float]:
    fit = result.systematic
    er, ser, eb, seb = fit.wheel_errors()
    mx, my, myaw = fit.mounting
    return {
        "radius_error": er - radius, "radius_std": ser, "base_error": eb - base,
        "base_std": seb, "mount_error": math.hypot(mx - MOUNTING[0], my - MOUNTING[1]),
        "mount_std": float(np.hypot(fit.stds[2], fit.stds[3])), "mount_yaw_deg": math.degrees(myaw),
        "k_trans": result.noise["per_distance"].values[0],
        "k_rot": result.noise["per_distance"].values[1],
        "pairs": result.pairs, "trimmed": fit.trimmed,
    }  # fmt: skip


def _summary(rows: list[dict[str, float]]) -> str:
    def worst(key: str) -> float:
        return max(abs(r[key]) for r in rows)

    def within(key: str, std: str) -> int:
        return sum(abs(r[key]) <= 3 * r[std] for r in rows)

    n = len(rows)
    return (
        f"{100 * worst('radius_error'):.3f} | {100 * np.mean([r['radius_std'] for r in rows]):.3f} "
        f"| {100 * worst('base_error'):.3f} | {100 * np.mean([r['base_std'] for r in rows]):.3f} "
        f"| {100 * worst('mount_error'):.2f} | {within('radius_error', 'radius_std')}/{n}, "
        f"{within('base_error', 'base_std')}/{n}"
    )


def main() -> str:
    load_before = os.getloadavg()[0]
    settings = CalibrationSettings()
    table: list[str] = []
    results: dict[str, Any] = {}
    t_ours = t_oracle = 0.0
    turned: list[float] = []
    cases = [*CASES, ("both, k_rot 0.01, glitches", CASES[-1][1])]
    rows: dict[str, tuple[list[dict[str, float]], list[dict[str, float]]]] = {
        name: ([], []) for name, _ in cases
    }
    for seed in SEEDS:
        base_run = load_dataset("rooms-laser", seed=seed, options={"laps": 6, "sigma_range": 0.01})
        mounted = remount_laser(base_run, MOUNTING, np.random.default_rng(1000 + seed))
        poses = base_run.truth.poses
        turned.append(float(np.sum(np.abs(np.angle(np.exp(1j * np.diff(poses[:, 2])))))))
        for name, model in cases:
            errors = model if name in GLITCHES else model.without_glitches()
            data, _ = corrupt_odometry(mounted, errors, np.random.default_rng(2000 + seed))
            radius, base = float(model.wheel_radius_error or 0), float(model.wheel_base_error or 0)
            t0 = time.perf_counter()
            pairs = scan_pairs(data)
            ours = calibrate_pairs(pairs, data.motion.noise_cov, settings)
            t_ours += time.perf_counter() - t0
            t0 = time.perf_counter()
            oracle = calibrate_pairs(_oracle(data, pairs), data.motion.noise_cov, settings)
            t_oracle += time.perf_counter() - t0
            rows[name][0].append(_row(ours, radius, base))
            rows[name][1].append(_row(oracle, radius, base))
    for name, (ours_rows, oracle_rows) in rows.items():
        table.append(f"| {name} | scan-matched | {_summary(ours_rows)} |")
        table.append(f"| {name} | oracle | {_summary(oracle_rows)} |")
        results[name] = {"scan_matched": ours_rows, "oracle": oracle_rows}
    load_after = os.getloadavg()[0]
    n = len(SEEDS) * len(cases)
    records = [Record(f"calibrate (match + fit), {n} runs", t_ours, "oracle fits alone", t_oracle)]
    head = (
        "| case | laser motions | worst radius error [%] | mean σ [%] | worst base error [%] "
        "| mean σ [%] | worst mounting error [cm] | within 3σ (radius, base) |\n"
        "|---|---|---:|---:|---:|---:|---:|---|"
    )
    notes = "\n".join(
        [
            f"Recovery over seeds {list(SEEDS)} (rooms tour, 6 laps, laser 1 cm noise mounted "
            f"at {MOUNTING} but stated at the centre; errors are estimate minus injected, "
            "in percentage points):",
            "",
            head,
            *table,
            "",
            "The wheel-base error is read from the turns, so its spread follows the random turn "
            f"noise: about k_rot / √(Σ|turn|); this tour turns {min(turned):.0f}-"
            f"{max(turned):.0f} rad in six laps, so k_rot = 0.03 rad/√rad (typical) gives "
            f"~{3 / math.sqrt(np.mean(turned)):.2f} % and 0.01 gives "
            f"~{1 / math.sqrt(np.mean(turned)):.2f} %.",
            f"Load average {load_before:.1f} before, {load_after:.1f} after (2 shared cores).",
        ]
    )
    markdown = write_results("calibration", records, notes=notes)
    payload = json.loads((RESULTS_DIR / "calibration.json").read_text(encoding="utf-8"))
    payload["recovery"] = results
    (RESULTS_DIR / "calibration.json").write_text(
        json.dumps(payload, indent=2) + "\n", encoding="utf-8"
    )
    return markdown


if __name__ == "__main__":
    print(main())
