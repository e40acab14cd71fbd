"""Victoria Park from the raw laser: slamkit's own tree detections against the published ones.

Two parts, both on the real data (``SLAMKIT_DATA``):

1. *Detections.* Every scan of the raw laser through :func:`slamkit.features.extract_trees`
   (timed), compared with the published (SLSJF) detections of ``victoria-park`` at the
   same scans (the clocks differ by 20.967 s): how many published detections we reproduce
   within 0.5 m, how many of ours are extra.
2. *Estimators.* EKF-SLAM, UKF-SLAM and FastSLAM 2.0 (the ``victoria-park-fastslam``
   preset, 100 particles) with their defaults and unknown association on
   ``victoria-park-trees`` (ours) and ``victoria-park`` (published) over the first
   ``--seconds`` of the drive (both data sets cut at the same odometry sample), scored
   against GPS: RMSE after SE(2) alignment, landmarks mapped, wall time. 'peer' is the run
   on the published detections.

    SLAMKIT_DATA=/work/shared/data PYTHONPATH=src python benchmarks/bench_victoria_park_raw.py \
        [--seconds 300]
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

from _common import Record, write_results
from slamkit.app.presets import get_preset
from slamkit.datasets import find_data_root, load_dataset
from slamkit.datasets.victoria_park_trees import match_published
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate

PRESET = get_preset("victoria-park-fastslam")
CASES: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("EKF-SLAM", "ekf-slam", {}),
    ("UKF-SLAM", "ukf-slam", {}),
    ("FastSLAM 2.0, 100 particles", "fastslam2", {**PRESET.settings, "n_particles": 100}),
)


def _score(name: str, config: dict[str, Any], ds: Any) -> tuple[float, float, Any]:
    wall = time.perf_counter()
    result = run(name, ds, config=config, seed=0)
    wall = time.perf_counter() - wall
    m = evaluate(result, ds).metrics
    d = m["diagnostics"]
    return (
        wall,
        m.get("gps", {}).get("rmse", float("nan")),
        d.get("n_landmarks", d.get("landmarks")),
    )


def main(seconds: float | None = 300.0) -> str:
    root = find_data_root()
    if root is None:
        return "bench_victoria_park_raw: skipped (no real data; set SLAMKIT_DATA)"
    load_before = os.getloadavg()[0]
    t_load = time.perf_counter()
    ours_all = load_dataset("victoria-park-trees", data_root=root)
    t_load = time.perf_counter() - t_load
    match = match_published(ours_all, load_dataset("victoria-park", data_root=root))
    opts = {} if seconds is None else {"max_duration_s": seconds}
    ours = load_dataset("victoria-park-trees", options=opts, data_root=root)
    pub = load_dataset("victoria-park", options=opts, data_root=root)
    records, rows = [], []
    for label, name, config in CASES:
        w_o, rmse_o, n_o = _score(name, config, ours)
        w_p, rmse_p, n_p = _score(name, config, pub)
        records.append(Record(f"{label}, first {seconds} s", w_o, "published detections", w_p))
        rows.append(
            f"| {label} | {rmse_o:.2f} | {rmse_p:.2f} | {n_o} | {n_p} | {w_o:.1f} | {w_p:.1f} |"
        )
    meta = ours_all.metadata
    table = "\n".join(
        [
            "| estimator | GPS RMSE ours [m] | GPS RMSE published [m] | landmarks ours | "
            "landmarks published | wall ours [s] | wall published [s] |",
            "|---|---:|---:|---:|---:|---:|---:|",
            *rows,
        ]
    )
    m = match
    notes = (
        f"Detections over the whole run: {meta['detections']} trunks in "
        f"{meta['reading_events']} of {meta['scans']} scans (median diameter "
        f"{meta['median_diameter_m']:.2f} m, {meta['circle_fits']} by circle fit), loading and "
        f"extracting {t_load:.1f} s. At the {m.scans} scans both have: {m.reproduced} of "
        f"{m.published} published detections reproduced within {m.radius} m "
        f"({100 * m.reproduced / max(m.published, 1):.1f} %), {m.extra} of our {m.ours} extra; "
        f"{m.not_compared} published stamps where we found no trunk. Estimators: first "
        f"{seconds} s, ids withheld, seed 0, defaults (FastSLAM 2.0: preset {PRESET.name}, "
        f"100 particles); GPS RMSE after SE(2) alignment, outliers rejected. Load average "
        f"(1 min) {load_before:.1f} before, {os.getloadavg()[0]:.1f} after, on "
        f"{os.cpu_count()} CPUs.\n\n{table}"
    )
    return write_results("victoria_park_raw", records, notes=notes)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=300.0, help="0: the whole run")
    args = parser.parse_args()
    print(main(args.seconds or None))
