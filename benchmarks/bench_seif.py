"""SEIF against EKF-SLAM over the whole Victoria Park run (ids withheld, as `slamkit run seif
--data victoria-park` does): wall and CPU time, the real-time factor, and the answer's quality
(GPS RMSE, landmarks, association accuracy). Needs the real data (``SLAMKIT_DATA``).

The machine is shared, so the two estimators run alternately, ``--repeats`` times each, in
the same process, and the best wall time of each is the one compared (the load average is
written down with them). Loading and evaluation are not timed (``slamkit.pipeline.run``
only, as in ``bench_victoria_park.py``). The profile of where SEIF's time goes, before and
after its batched steps, is in ``docs/estimators/seif.md``.

    python benchmarks/bench_seif.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from _common import Record, write_results
from slamkit.datasets import find_data_root, load_dataset
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.runtime import blas_thread_counts, blas_threads

CASES = (("SEIF", "seif"), ("EKF-SLAM, nearest neighbour", "ekf-slam"))


def main(repeats: int = 3) -> str:
    root = find_data_root()
    if root is None:
        return "bench_seif: skipped (no real data; set SLAMKIT_DATA)"
    ds = load_dataset("victoria-park", data_root=root)
    duration = ds.events[-1].t - ds.events[0].t
    load_before = os.getloadavg()[0]
    with blas_threads():
        run_threads = blas_thread_counts()
    walls: dict[str, list[float]] = {name: [] for _, name in CASES}
    cpus: dict[str, list[float]] = {name: [] for _, name in CASES}
    metrics = {}
    for _ in range(repeats):
        for _, name in CASES:  # alternately, so both see the same load
            wall, cpu = time.perf_counter(), time.process_time()
            result = run(name, ds, seed=0)
            walls[name].append(time.perf_counter() - wall)
            cpus[name].append(time.process_time() - cpu)
            metrics[name] = evaluate(result, ds).metrics
    best = {name: min(w) for name, w in walls.items()}
    records = [
        Record("SEIF: whole run", best["seif"], "EKF-SLAM (slamkit), same run", best["ekf-slam"]),
        *(
            Record(f"{label}: whole run", best[name], "the data's duration", duration)
            for label, name in CASES
        ),
    ]
    rows = []
    for label, name in CASES:
        m = metrics[name]
        g, a = m.get("gps", {}), m.get("association", {})
        rows.append(
            f"| {label} | {best[name]:.1f} | {statistics.median(walls[name]):.1f} | "
            f"{min(cpus[name]):.1f} | {duration / best[name]:.1f}× | "
            f"{g.get('rmse', float('nan')):.3f} | {m['diagnostics'].get('n_landmarks')} | "
            f"{a.get('accuracy', float('nan')):.4f} |"
        )
    table = "\n".join(
        [
            "| estimator | best wall [s] | median wall [s] | best CPU [s] | faster than real "
            "time | GPS RMSE [m] | landmarks | association accuracy |",
            "|---|---:|---:|---:|---:|---:|---:|---:|",
            *rows,
        ]
    )
    notes = (
        f"Victoria Park, {duration:.0f} s of data, ids withheld (the feature index scores the "
        f"association only), default settings of both, seed 0. {repeats} runs of each, "
        f"alternating; best and median wall time, best CPU time. Load average (1 min) "
        f"{load_before:.1f} before, {os.getloadavg()[0]:.1f} after, on {os.cpu_count()} CPUs "
        f"shared with other jobs; BLAS threads in the runs {run_threads}. GPS RMSE after "
        f"SE(2) alignment at the fixes, outliers rejected (slamkit.eval.gps).\n\n{table}"
    )
    return write_results("seif", records, notes=notes)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description="SEIF against EKF-SLAM on Victoria Park")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each estimator")
    print(main(parser.parse_args().repeats))
