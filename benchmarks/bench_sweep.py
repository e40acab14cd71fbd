"""Sweeps on Dask: runs per minute with 1 and 2 local workers, against the same runs done
one after another in one process (``slamkit.app.run_job``, what ``slamkit run`` does).

The workload: EKF localization on ``five-features`` driven ten laps (a little over a
second a run with loading, evaluation and the output folder), 16 seeds, no plots. The
workers are started and warmed up before the clock starts (one run on each, which starts
its job process and imports slamkit there); cluster start-up is reported apart. The
overhead per task (keying, scheduling, handing the task to the job process, shipping the
outcome, the table written as results arrive) is ``(sweep with 1 worker − sequential) /
runs``. The machine is shared and its timings wander by ±20 %, so the three measurements are
taken ``REPEATS`` times, interleaved; the times compared are their medians, the overhead the
median of the repeats' differences (each repeat's sequential and 1-worker times are taken
one right after the other).

    python benchmarks/bench_sweep.py
"""

from __future__ import annotations

import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from _common import Record, write_results
from slamkit.app import RunRequest, run_job
from slamkit.sweep import local_cluster, parse_spec, run_sweep
from slamkit.sweep.execute import RunTask, execute_task, plan_sweep

RUNS = 16
REPEATS = 5
SPEC: dict[str, Any] = {
    "sweep": {
        "name": "bench",
        "estimators": ["ekf-localization"],
        "datasets": ["five-features"],
        "seeds": RUNS,
    },
    "dataset": {"laps": 10},
}


def _sequential(folder: Path) -> float:
    start = time.perf_counter()
    for p in parse_spec(SPEC).points():
        run_job(
            RunRequest(
                p.estimator,
                p.dataset,
                folder / f"seed-{p.seed}",
                seed=p.seed,
                dataset_options=p.dataset_options,
                plots=False,
            )
        )
    return time.perf_counter() - start


def _warm_up(client: Any, folder: Path) -> None:
    """One run on every worker, so that each worker thread's job process is started and
    has imported slamkit before the clock starts."""
    warm = {**SPEC, "sweep": {**SPEC["sweep"], "seeds": [10_000]}}
    ((key, point),) = plan_sweep(parse_spec(warm))
    futures = [
        client.submit(
            execute_task, RunTask(key, point, str(folder / str(i))), workers=[addr], pure=False
        )
        for i, addr in enumerate(client.nthreads())
    ]
    if not all(f.result().ok for f in futures):
        raise RuntimeError("a warm-up run failed")


def _sweep(workers: int, folder: Path) -> tuple[float, float]:
    """Seconds of the sweep on a warm cluster, and the cluster's start-up seconds."""
    from distributed import Client

    start = time.perf_counter()
    cluster = local_cluster(workers)
    client = Client(cluster)
    _warm_up(client, folder / "warm")
    startup = time.perf_counter() - start
    try:
        start = time.perf_counter()
        result = run_sweep(SPEC, folder / "sweep", client=client)
        seconds = time.perf_counter() - start
    finally:
        client.close()
        cluster.close()
    if result.executed != RUNS or result.failed:
        raise RuntimeError(f"sweep ran {result.executed} of {RUNS}, {result.failed} failed")
    return seconds, startup


def _spread(times: list[float]) -> str:
    return f"{min(times):.1f}-{max(times):.1f}"


def main() -> str:
    root = Path(tempfile.mkdtemp(prefix="bench-sweep-"))
    load_before = os.getloadavg()[0]
    try:
        # warm this process too (imports, caches), then time the sequential loop
        run_job(RunRequest("ekf-localization", "five-features", root / "warm", plots=False))
        seq, one, two = [], [], []
        for i in range(REPEATS):
            seq.append(_sequential(root / f"seq-{i}"))
            one.append(_sweep(1, root / f"one-{i}"))
            two.append(_sweep(2, root / f"two-{i}"))
    finally:
        shutil.rmtree(root, ignore_errors=True)
    load_after = os.getloadavg()[0]
    t_seq = statistics.median(seq)
    t_one, start_one = (statistics.median(x) for x in zip(*one, strict=True))
    t_two, start_two = (statistics.median(x) for x in zip(*two, strict=True))
    per_run = t_seq / RUNS
    paired = [(t - s) / RUNS for (t, _), s in zip(one, seq, strict=True)]
    overhead = statistics.median(paired)
    records = [
        Record(f"{RUNS} runs, sweep on 1 worker", t_one, "sequential run_job", t_seq),
        Record(f"{RUNS} runs, sweep on 2 workers", t_two, "sequential run_job", t_seq),
        Record(f"{RUNS} runs, sweep on 2 workers", t_two, "sweep on 1 worker", t_one),
    ]
    notes = (
        f"EKF localization on five-features, {SPEC['dataset']['laps']} laps, {RUNS} seeds, "
        f"no plots; medians of "
        f"{REPEATS} interleaved repeats (sequential {_spread(seq)} s, 1 worker "
        f"{_spread([t for t, _ in one])} s, 2 workers {_spread([t for t, _ in two])} s); "
        f"{per_run:.2f} s per run sequentially. Runs per minute: sequential "
        f"{60 * RUNS / t_seq:.1f}, 1 worker {60 * RUNS / t_one:.1f}, 2 workers "
        f"{60 * RUNS / t_two:.1f} ({t_one / t_two:.2f}x the 1-worker rate). Overhead per task "
        f"against the bare run: {1000 * overhead:.0f} ms ({100 * overhead / per_run:.1f} %), "
        f"the median of the {REPEATS} repeats' differences "
        f"({1000 * min(paired):.0f} to {1000 * max(paired):.0f} ms). "
        f"Cluster start-up with warm-up: {start_one:.1f} s (1 worker), {start_two:.1f} s "
        f"(2 workers), not in the times. Load average (1 min) {load_before:.1f} before, "
        f"{load_after:.1f} after, on {os.cpu_count()} CPUs (the machine is shared)."
    )
    return write_results("sweep", records, notes=notes)


if __name__ == "__main__":
    print(main())
