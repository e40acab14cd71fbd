"""Victoria Park end to end: EKF-SLAM and FastSLAM over the whole run, without the feature
index, against the data's own duration (a real-time factor) — and how good the answer is.

Targets of the landmark-SLAM issue: EKF-SLAM in under 60 s; FastSLAM with 100 particles
faster than the data (about 26 minutes). Each estimator runs once over the whole stream
(``slamkit.pipeline.run``, as ``slamkit run`` does; loading and evaluation not timed); the
result is scored against the GPS (outliers rejected, SE(2)-aligned at the fixes) and its
data association against the file's feature index. Needs the real data (``SLAMKIT_DATA``).

    python benchmarks/bench_victoria_park.py
"""

from __future__ import annotations

import os
import time
from typing import Any

from _common import Record, write_results
from slamkit.app.presets import get_preset
from slamkit.datasets import find_data_root, load_dataset
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.runtime import blas_thread_counts, blas_threads

PRESET = get_preset("victoria-park-fastslam")
CASES: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("EKF-SLAM, nearest neighbour", "ekf-slam", {}),
    ("FastSLAM 1.0, 100 particles", "fastslam1", {**PRESET.settings, "n_particles": 100}),
    ("FastSLAM 2.0, 100 particles", "fastslam2", {**PRESET.settings, "n_particles": 100}),
)


def main() -> str:
    root = find_data_root()
    if root is None:
        return "bench_victoria_park: skipped (no real data; set SLAMKIT_DATA)"
    ds = load_dataset("victoria-park", data_root=root)
    duration = ds.events[-1].t - ds.events[0].t
    load_before = os.getloadavg()[0]
    with blas_threads():  # what run() holds BLAS to here: the policy, or the environment's
        run_threads = blas_thread_counts()
    records, rows = [], []
    for label, name, config in CASES:
        wall, cpu = time.perf_counter(), time.process_time()
        result = run(name, ds, config=config, seed=0)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        m = evaluate(result, ds).metrics
        records.append(Record(f"{label}: whole run", wall, "the data's duration", duration))
        a, g = m.get("association", {}), m.get("gps", {})
        rows.append(
            f"| {label} | {wall:.1f} | {cpu:.1f} | {duration / wall:.1f}× | "
            f"{g.get('rmse', float('nan')):.2f} | {g.get('median', float('nan')):.2f} | "
            f"{m['diagnostics'].get('n_landmarks', m['diagnostics'].get('landmarks'))} | "
            f"{a.get('accuracy', float('nan')):.4f} | {a.get('duplicates', '—')} |"
        )
    table = "\n".join(
        [
            "| estimator | wall [s] | CPU [s] | faster than real time | GPS RMSE [m] | "
            "GPS median [m] | landmarks | association accuracy | duplicates |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
            *rows,
        ]
    )
    dead = evaluate(run("dead-reckoning", ds), ds).metrics["gps"]["rmse"]
    notes = (
        f"Victoria Park, {duration:.0f} s of data, {ds.counts().get('LandmarkReadings', 0)} "
        f"detection events, ids withheld (the feature index scores the association only). "
        f"'peer' is the data's duration, so the ratio is the real-time factor. One run each, "
        f"seed 0. Load average (1 min) {load_before:.1f} before, {os.getloadavg()[0]:.1f} "
        f"after, on {os.cpu_count()} CPUs; BLAS threads in the runs {run_threads} (slamkit's "
        f"policy in this environment, slamkit.runtime; no thread variable needed). GPS RMSE "
        f"after SE(2) alignment "
        f"at the fixes, outliers rejected (slamkit.eval.gps); dead reckoning: {dead:.1f} m. "
        f"Settings: FastSLAM with the preset {PRESET.name} ({dict(PRESET.settings)}, see "
        f"docs/presets.md), 100 particles.\n\n"
        f"{table}"
    )
    return write_results("victoria_park", records, notes=notes)


if __name__ == "__main__":
    print(main())
