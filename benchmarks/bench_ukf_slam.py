"""UKF-SLAM against EKF-SLAM on the same data, in the same run: consistency over seeds on
simulated worlds, Victoria Park (GPS RMSE) and MRCLAM (the landmark map against the Vicon
survey), with the time per step.

* **Consistency** (``slamkit.sim``, the five-feature world, known ids): pose NEES (χ²₃) at
  every scan over ``SEEDS`` seeded runs; the average over runs is compared at each scan
  with its two-sided 95 % band (``chi2_bounds(3, SEEDS)``), and the share of scans outside
  it is given with the mean over runs and scans. Landmark NEES (χ²₂, the final map), mean
  NIS and the final position error too. Two regimes: the nominal world driven twice
  (readings every 0.2 s), and one lap with three times the heading noise and readings
  every 0.5 s (more non-linearity between updates).
* **Victoria Park**: the whole run, ids withheld, nearest neighbour (as
  ``bench_victoria_park.py``): GPS RMSE after an SE(2) alignment at the fixes.
* **MRCLAM** Dataset 1 Robot 1 (``mrclam1``, landmarks not given): the map against the
  Vicon survey (SE(2)-aligned), with the barcodes as ids and without.

The real data need ``SLAMKIT_DATA``; without it those rows are left out. Each timed case
runs once (seed 0), loading and scoring not timed; the "time per step" is the estimator's
wall time over the runner's steps (distinct time stamps).

    python benchmarks/bench_ukf_slam.py
"""

from __future__ import annotations

import math
import os
import time
from typing import Any

import numpy as np

from _common import Record, write_results
from slamkit.datasets import Dataset, LandmarkReadings, find_data_root, load_dataset
from slamkit.datasets.stream import group_by_time
from slamkit.eval import chi2_bounds, nees, pose_errors
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.slam import EkfSlam, EkfSlamConfig, UkfSlam, UkfSlamConfig

SEEDS = 100
"""Seeded runs per regime in the consistency study."""

REGIMES: tuple[tuple[str, dict[str, Any]], ...] = (
    ("five-features, 2 laps, readings every 0.2 s", {"laps": 2, "observe_every": 2}),
    (
        "five-features, 1 lap, heading noise 15 deg/s, readings every 0.5 s",
        {"sigma_omega_deg": 15.0, "observe_every": 5},
    ),
)
FILTERS: tuple[tuple[str, type[EkfSlam], EkfSlamConfig], ...] = (
    ("EKF-SLAM", EkfSlam, EkfSlamConfig()),
    ("UKF-SLAM", UkfSlam, UkfSlamConfig()),
)


def steps(ds: Dataset) -> int:
    """The runner's steps: distinct time stamps."""
    return sum(1 for _ in group_by_time(ds.events))


def one_run(cls: type[EkfSlam], config: EkfSlamConfig, ds: Dataset) -> dict[str, Any]:
    """One seeded run: pose NEES at every scan, final landmark NEES, NIS, final error."""
    assert ds.truth.poses is not None and ds.truth.landmarks is not None
    row = {t: i for i, t in enumerate(ds.truth.times.tolist())}
    est = cls(ds, config, np.random.default_rng(0))
    rows, poses, covs = [], [], []
    wall = 0.0
    for ev in ds.events:
        t0 = time.perf_counter()
        est.handle(ev)
        wall += time.perf_counter() - t0
        if isinstance(ev, LandmarkReadings):
            p = est.estimate()
            rows.append(row[ev.t])
            poses.append(p.pose)
            covs.append(p.cov)
    out = est.finish()
    assert out.landmarks is not None and out.landmarks.covariances is not None
    assert out.innovations is not None
    m = out.landmarks.landmarks
    err = m.positions - ds.truth.landmarks.position_of(m.ids)
    final = pose_errors(est.estimate().pose, ds.truth.poses[-1])
    return {
        "pose_nees": nees(pose_errors(np.array(poses), ds.truth.poses[rows]), np.array(covs)),
        "landmark_nees": nees(err, out.landmarks.covariances),
        "nis": out.innovations.nis,
        "final_xy": math.hypot(final[0], final[1]),
        "wall": wall,
        "steps": steps(ds),
    }


def consistency(options: dict[str, Any]) -> dict[str, dict[str, float]]:
    """Both filters over SEEDS seeds of one regime: a summary per filter."""
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name, _, _ in FILTERS}
    for seed in range(SEEDS):
        ds = load_dataset("five-features", seed=seed, options=options)
        for name, cls, config in FILTERS:
            runs[name].append(one_run(cls, config, ds))
    lo, hi = chi2_bounds(3, SEEDS)
    out = {}
    for name, rs in runs.items():
        T = min(r["pose_nees"].size for r in rs)
        P = np.array([r["pose_nees"][:T] for r in rs])
        avg = P.mean(axis=0)
        L = np.concatenate([r["landmark_nees"] for r in rs])
        out[name] = {
            "pose_nees": float(P.mean()),
            "above": float(np.mean(avg > hi)),
            "below": float(np.mean(avg < lo)),
            "landmark_nees": float(L.mean()),
            "landmark_band_hi": chi2_bounds(2, L.size)[1],
            "nis": float(np.concatenate([r["nis"] for r in rs]).mean()),
            "final_xy": float(np.sqrt(np.mean([r["final_xy"] ** 2 for r in rs]))),
            "wall": float(sum(r["wall"] for r in rs)),
            "ms_per_step": 1e3 * sum(r["wall"] for r in rs) / sum(r["steps"] for r in rs),
        }
    return out


def real_case(data: str, options: dict[str, Any], config: dict[str, Any], root: Any) -> list[Any]:
    """EKF-SLAM and UKF-SLAM on one real data set: ``[(filter, wall, steps, metrics)]``."""
    ds = load_dataset(data, options=options, data_root=root)
    n = steps(ds)
    out = []
    for name in ("ekf-slam", "ukf-slam"):
        wall = time.perf_counter()
        result = run(name, ds, config=config, seed=0)
        wall = time.perf_counter() - wall
        out.append((name, wall, n, evaluate(result, ds).metrics))
    return out


def main() -> str:
    load_before = os.getloadavg()[0]
    records: list[Record] = []
    lines = [
        f"### Consistency over {SEEDS} seeds (known ids)",
        "",
        "Pose NEES: mean over runs and scans (χ²₃: 3); 'above' / 'below': share of the scans "
        f"whose {SEEDS}-run average leaves its 95 % band (2.5 % each for a consistent filter). "
        "Landmark NEES: the final map (χ²₂: 2; the band's upper end given). Final position: "
        "RMS over runs. Time: the estimator's calls, summed over the runs.",
        "",
        "| regime | filter | pose NEES | above | below | landmark NEES (band hi) | mean NIS "
        "| final position RMS [m] | ms per step |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, options in REGIMES:
        summary = consistency(options)
        for name, s in summary.items():
            lines.append(
                f"| {label} | {name} | {s['pose_nees']:.2f} | {100 * s['above']:.1f} % | "
                f"{100 * s['below']:.1f} % | {s['landmark_nees']:.2f} "
                f"({s['landmark_band_hi']:.2f}) | {s['nis']:.2f} | {s['final_xy']:.3f} | "
                f"{s['ms_per_step']:.3f} |"
            )
        ekf, ukf = summary["EKF-SLAM"], summary["UKF-SLAM"]
        records.append(Record(f"{label}: {SEEDS} runs, UKF-SLAM", ukf["wall"], "EKF-SLAM",
                              ekf["wall"]))  # fmt: skip
    root = find_data_root()
    if root is None:
        lines += ["", "Real data: skipped (no SLAMKIT_DATA)."]
    else:
        lines += [
            "",
            "### Real data (seed 0, one run each)",
            "",
            "| data | filter | wall [s] | ms per step | GPS RMSE [m] | ATE RMSE [m] | "
            "landmarks | landmark RMSE vs survey [m] | association accuracy |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|",
        ]
        cases = (
            ("victoria-park", "Victoria Park, ids withheld (NN)", {}, {}),
            ("mrclam1", "MRCLAM 1 robot 1, barcodes as ids", {"landmarks_known": False}, {}),
            ("mrclam1", "MRCLAM 1 robot 1, no ids (NN)", {"landmarks_known": False},
             {"use_ids": False}),
        )  # fmt: skip
        for data, label, options, config in cases:
            res = real_case(data, options, config, root)
            for name, wall, n, m in res:
                g, lm, a = m.get("gps", {}), m.get("landmarks", {}), m.get("association", {})
                lines.append(
                    f"| {label} | {name} | {wall:.1f} | {1e3 * wall / n:.2f} | "
                    f"{g.get('rmse', float('nan')):.2f} | "
                    f"{m.get('ate', {}).get('rmse', float('nan')):.3f} | "
                    f"{m['diagnostics'].get('n_landmarks')} | "
                    f"{lm.get('rmse', float('nan')):.3f} | "
                    f"{a.get('accuracy', float('nan')):.4f} |"
                )
            (_, ekf_wall, _, _), (_, ukf_wall, _, _) = res
            records.append(Record(f"{label}: UKF-SLAM", ukf_wall, "EKF-SLAM", ekf_wall))
    notes = (
        "UKF-SLAM (slamkit.slam.ukf_slam) against EKF-SLAM with the same defaults, the same "
        "association, provisional list and checks: only the Gaussian approximation differs. "
        "'peer' is EKF-SLAM, so the ratio below 1 is the UKF's extra cost. Load average "
        f"(1 min) {load_before:.1f} before, {os.getloadavg()[0]:.1f} after, on "
        f"{os.cpu_count()} CPUs: other jobs share the machine, so compare the two filters "
        "within one run. MRCLAM as loaded carries no true path (ATE nan); association "
        "accuracy needs a feature index (Victoria Park's).\n\n" + "\n".join(lines)
    )
    return write_results("ukf_slam", records, notes=notes)


if __name__ == "__main__":
    print(main())
