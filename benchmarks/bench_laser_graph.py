"""Graph-based laser SLAM (``graph-slam``) on the raw Freiburg logs (Intel, ACES, Freiburg
079), scored by the relation metric (mean ± std of the translational [m] and rotational
[deg] errors over all relations), with the whole-log CPU and wall time.

Published (Kümmerle et al., Autonomous Robots 27(4), 2009; ``DATA.md``), translational:
graph mapping Intel 0.031, ACES 0.044, Freiburg 079 0.056 m; Cartographer (Hess et al.,
ICRA 2016) 0.0229 / 0.0375 / 0.0452 m and 0.45 / 0.37 / 0.54°, its wall time for the whole
log 179 / 41 / 62 s (a Xeon E5-1650, up to four background threads). No peer runs here:
those figures are quoted beside ours (the records' "peer" is Cartographer's published wall
time). Each estimator runs once over the stream (``slamkit.pipeline.run``, as ``slamkit
run`` does; loading and scoring not timed). Needs the real data (``SLAMKIT_DATA``).

    python benchmarks/bench_laser_graph.py [intel-raw aces-raw fr079-raw] [--seconds S]
    python benchmarks/bench_laser_graph.py --perturb 1e-6 --perturb-seeds 1 2 3 4

``--perturb SCALE``: every real range (above 0.1 m, below the max range: a reading at the
max range stays "no return") moved by Gaussian noise of standard deviation ``SCALE`` [m]
(``numpy.random.default_rng(seed)``), one run per seed, results to
``results/laser_graph_perturbed.*``: how much of a score is where the closure decisions
happen to fall (``docs/estimators/laser_graph.md``, "Robustness").
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

import numpy as np

from _common import Record, write_results
from slamkit.datasets import Dataset, LaserScan, find_data_root, load_dataset
from slamkit.eval.relations import relation_errors
from slamkit.pipeline import run

PUBLISHED = {
    # name: (label, graph mapping m, Cartographer m, Cartographer deg, Cartographer wall s)
    "intel-raw": ("Intel", 0.031, 0.0229, 0.453, 179.0),
    "aces-raw": ("ACES", 0.044, 0.0375, 0.373, 41.0),
    "fr079-raw": ("Freiburg 079", 0.056, 0.0452, 0.538, 62.0),
}


def main() -> str:
    parser = argparse.ArgumentParser()
    parser.add_argument("logs", nargs="*", default=list(PUBLISHED))
    parser.add_argument("--seconds", type=float, default=None, help="only the first S seconds")
    parser.add_argument("--perturb", type=float, default=0.0, help="range noise [m]")
    parser.add_argument("--perturb-seeds", type=int, nargs="*", default=[1, 2, 3, 4])
    args = parser.parse_args()
    seeds = args.perturb_seeds if args.perturb > 0 else [None]
    root = find_data_root()
    if root is None:
        return "bench_laser_graph: skipped (no real data; set SLAMKIT_DATA)"
    load_before = os.getloadavg()[0]
    records, rows = [], []
    for name, seed in [(n, s) for n in args.logs for s in seeds]:
        label, graph_mapping, carto_m, carto_deg, carto_wall = PUBLISHED[name]
        data = load_dataset(name, data_root=root)
        if args.seconds is not None:
            t0 = data.events[0].t
            events = tuple(e for e in data.events if e.t <= t0 + args.seconds)
            data = dataclasses.replace(data, events=events)
            label = f"{label} (first {args.seconds:.0f} s)"
        if seed is not None:
            data = _perturbed(data, args.perturb, seed)
            label = f"{label}, ranges ± {args.perturb:g} m (seed {seed})"
        cpu, wall = time.process_time(), time.perf_counter()
        result = run("graph-slam", data, seed=0)
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        rel = relation_errors(result.times, result.poses, data.truth.relations)
        d = result.output.diagnostics
        duration = data.events[-1].t - data.events[0].t
        records.append(Record(f"{label}: graph SLAM", wall, "Cartographer (published)", carto_wall))
        rows.append(
            f"| {label} | {rel.summary()} | {graph_mapping:.3f} m | {carto_m:.4f} m, "
            f"{carto_deg:.2f}° | {d['keyframes']} | {d['loops_kept']} | {cpu:.0f} | {wall:.0f} "
            f"| {duration:.0f} |"
        )
        print(rows[-1], flush=True)
    table = "\n".join(
        [
            "| log | graph SLAM, all relations | published graph mapping | published "
            "Cartographer | keyframes | closures | CPU [s] | wall [s] | data [s] |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|",
            *rows,
        ]
    )
    notes = (
        "Default LaserGraphConfig, seed 0. Relation errors: mean ± std, translation [m] and "
        "rotation [deg], over every relation the run covers. Published graph mapping and "
        "Cartographer figures are quoted, not run here. Load average before the run: "
        f"{load_before:.1f} (the machine is shared: wall times above the CPU times are waiting)."
        "\n\n" + table
    )
    name = "laser_graph" if args.perturb <= 0 else "laser_graph_perturbed"
    return write_results(name, records, notes=notes) + "\n\n" + table


def _perturbed(data: Dataset, scale: float, seed: int) -> Dataset:
    """``data`` with every real range moved by ``N(0, scale²)`` (module docstring)."""
    rng = np.random.default_rng(seed)
    assert data.laser is not None
    top = data.laser.max_range - 0.01
    events = []
    for e in data.events:
        if isinstance(e, LaserScan):
            r = np.asarray(e.ranges, dtype=np.float64)
            real = np.isfinite(r) & (r > 0.1) & (r < top)
            noise = scale * rng.standard_normal(r.shape)
            e = dataclasses.replace(e, ranges=np.where(real, r + noise, r))
        events.append(e)
    return dataclasses.replace(data, events=tuple(events))


if __name__ == "__main__":
    print(main())
