"""Laser odometry on the raw Freiburg logs (Intel, ACES, Freiburg 079), scored by the relation
metric against the published "scan matching" column, with the whole-log wall time against
the log's own duration (a real-time factor).

Published (Kümmerle et al., Autonomous Robots 27(4), 2009; ``DATA.md``), mean ± std of the
translational relation error: scan matching Intel 0.220 ± 0.296 m, ACES 0.173 ± 0.614 m,
Freiburg 079 0.258 ± 0.427 m. No peer runs here: those figures are quoted beside ours, and
the robot's raw odometry (dead reckoning over the same stream) is scored in the same run.
Cartographer's published wall time for the whole log (Hess et al., ICRA 2016, a Xeon with up
to 4 threads): Intel 179 s, ACES 41 s, Freiburg 079 62 s. Each estimator runs once over the
stream (``slamkit.pipeline.run``, as ``slamkit run`` does; loading and scoring not timed).
Needs the real data (``SLAMKIT_DATA``).

    python benchmarks/bench_laser_odometry.py
"""

from __future__ import annotations

import os
import time

import numpy as np

from _common import Record, write_results
from slamkit.datasets import find_data_root, load_dataset
from slamkit.eval.relations import relation_errors, select_relations
from slamkit.pipeline import run

LOGS = (
    ("Intel", "intel-raw", (0.220, 0.296)),
    ("ACES", "aces-raw", (0.173, 0.614)),
    ("Freiburg 079", "fr079-raw", (0.258, 0.427)),
)
SHORT = 3.0
"""Relations no longer than this [s] are also scored alone: local accuracy, without the drift
that only a loop closure removes."""


def _scores(times: np.ndarray, poses: np.ndarray, relations) -> tuple[str, str]:
    every = relation_errors(times, poses, relations)
    short = relation_errors(times, poses, select_relations(relations, max_duration=SHORT))
    return every.summary(), short.summary()


def main() -> str:
    root = find_data_root()
    if root is None:
        return "bench_laser_odometry: skipped (no real data; set SLAMKIT_DATA)"
    load_before = os.getloadavg()[0]
    records, rows = [], []
    for label, name, published in LOGS:
        ds = load_dataset(name, data_root=root)
        relations = ds.truth.relations
        assert relations is not None
        duration = ds.events[-1].t - ds.events[0].t
        wall = time.perf_counter()
        result = run("laser-odometry", ds, seed=0)
        wall = time.perf_counter() - wall
        dead = run("dead-reckoning", ds, seed=0)
        ours_all, ours_short = _scores(result.times, result.poses, relations)
        odo_all, odo_short = _scores(dead.times, dead.poses, relations)
        records.append(Record(f"{label}: laser odometry, whole log", wall, "real time", duration))
        rows.append(
            f"| {label} | {ours_all} | {ours_short} | {published[0]:.3f} ± {published[1]:.3f} m "
            f"| {odo_all} | {odo_short} | {wall:.1f} | {duration / wall:.0f}× |"
        )
    table = "\n".join(
        [
            "| log | laser odometry, all relations | ≤ 3 s | published scan matching | "
            "raw odometry, all | raw odometry, ≤ 3 s | wall [s] | faster than real time |",
            "|---|---|---|---:|---|---|---:|---:|",
            *rows,
        ]
    )
    notes = (
        "Default LaserOdometryConfig (scan-to-map normal ICP with the odometry prior; a match "
        "that fits the map poorly, fails or is gated relocated over every heading and judged "
        "against the wheels by surface fit, scanmatch.relocate). "
        "Relation errors: mean ± std, translation [m] and rotation [deg], and the share of "
        "relations covered. Published scan-matching figures and Cartographer's wall time are "
        f"quoted, not run here. Load average before the run: {load_before:.1f}.\n\n" + table
    )
    return write_results("laser_odometry", records, notes=notes) + "\n\n" + table


if __name__ == "__main__":
    print(main())
