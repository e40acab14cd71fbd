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
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

from _common import Record, write_results
from slamkit.datasets import find_data_root, load_dataset
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
    args = parser.parse_args()
    root = find_data_root()
    if root is None:
        return "bench_laser_graph: skipped (no real data; set SLAMKIT_DATA)"
    load_before = os.getloadavg()[0]
    records, rows = [], []
    for name in args.logs:
        label, graph_mapping, carto_m, carto_deg, carto_wall = PUBLISHED[name]
        data = load_dataset(name, data_root=root)
        if args.seconds is not None:
            t0 = data.events[0].t
            events = tuple(e for e in data.events if e.t <= t0 + args.seconds)
            data = dataclasses.replace(data, events=events)
            label = f"{label} (first {args.seconds:.0f} s)"
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
    return write_results("laser_graph", records, notes=notes) + "\n\n" + table


if __name__ == "__main__":
    print(main())
