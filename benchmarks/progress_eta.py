"""How honest the progress bar's time left is: graph-slam over a real log, timed per count.

For the moments at 25, 50, 75 and 90 % of the work it prints the time truly left and the
time left estimated four ways: from the mean rate since the start counted in scans, the
same counted in events (the bar before it counted scans), from the rate of the last
30 s (``slamkit.pipeline.eta.RATE_WINDOW``), and the range the bar and the plain line give
(:class:`slamkit.pipeline.eta.TimeLeft` with the estimator's pace: for graph SLAM from the
last 30 s's pace holding to the pace rising as it has since the start)::

    PYTHONPATH=src python benchmarks/progress_eta.py "$SLAMKIT_DATA/laser/rosbags/intel.bag"

The table in ``docs/architecture.md`` ("Progress") came from it.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from slamkit.datasets.files import load_data
from slamkit.pipeline import get_estimator_entry, run, work_measure
from slamkit.pipeline.eta import RATE_WINDOW, TimeLeft


def main(path: str, estimator: str = "graph-slam") -> None:
    dataset = load_data(path)
    entry = get_estimator_entry(estimator)
    measure = work_measure(entry, dataset)
    units_after = np.cumsum(measure.weights)  # units done after each event
    counts: list[tuple[float, int]] = []
    marks: dict[str, float] = {}
    t0 = time.perf_counter()
    run(
        entry,
        dataset,
        progress=lambda done, total: counts.append((time.perf_counter() - t0, done)),
        stage=lambda text: marks.setdefault("last step", time.perf_counter() - t0),
    )
    t_end = time.perf_counter() - t0
    total, events = measure.total, len(dataset)
    print(
        f"{path}: {events:,} events, {total:,} {measure.unit}; run {t_end:.1f} s, "
        f"of which the last step {t_end - marks['last step']:.1f} s"
    )
    for share in (0.25, 0.5, 0.75, 0.9):
        i = next(k for k, (_, d) in enumerate(counts) if d >= share * total)
        t, done = counts[i]
        done_events = int(np.searchsorted(units_after, done, side="left")) + 1
        j = next(k for k, (tk, _) in enumerate(counts) if tk >= t - RATE_WINDOW)
        t_then, done_then = counts[j - 1] if j > 0 else (0.0, 0)
        window = (total - done) * (t - t_then) / max(done - done_then, 1)
        bar = TimeLeft(measure.pace)
        for tk, dk in counts[: i + 1]:
            bar.add(tk, dk)
        low, high = bar.estimate(total) or (float("nan"), float("nan"))
        print(
            f"  {100 * done / total:3.0f} % of {measure.unit} "
            f"({100 * done_events / events:3.0f} % of events) at {t:5.1f} s: truly "
            f"{t_end - t:5.1f} s left; mean rate in {measure.unit} {t * (total - done) / done:5.1f}"
            f" s, in events {t * (events - done_events) / done_events:5.1f} s, "
            f"last {RATE_WINDOW:.0f} s {window:5.1f} s; the bar {low:5.1f} to {high:5.1f} s"
        )


if __name__ == "__main__":
    main(*sys.argv[1:])
