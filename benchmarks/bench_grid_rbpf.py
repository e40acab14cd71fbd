"""Grid-based RBPF SLAM (``grid-rbpf``, 30 particles, the defaults) on the raw Freiburg logs
(Intel, ACES, Freiburg 079), scored by the relation metric (mean ± std of the translational
[m] and rotational [deg] errors over all relations), with the whole-log wall and CPU time
against the data's own duration, and the peak memory: the resident set of a process that
runs that log alone, and the peak bytes of the particles' shared map tiles.

Published (Kümmerle et al., Autonomous Robots 27(4), 2009; ``DATA.md``): the RBPF with 50
particles, Intel 0.070 ± 0.083 m, ACES 0.060 ± 0.049 m, Freiburg 079 0.061 ± 0.044 m —
quoted, not run here (no peer runs here; the records' "peer" is the data's duration, the
real-time budget). Each log runs in a child process of its own so that its peak RSS is its
own. Needs the real data (``SLAMKIT_DATA``).

    python benchmarks/bench_grid_rbpf.py [intel-raw aces-raw fr079-raw] [--seeds 0 1]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

from _common import Record, write_results
from slamkit.datasets import find_data_root, load_dataset
from slamkit.eval.relations import relation_errors
from slamkit.pipeline import run

PUBLISHED = {
    # name: (label, published RBPF mean m, std m)
    "intel-raw": ("Intel", 0.070, 0.083),
    "aces-raw": ("ACES", 0.060, 0.049),
    "fr079-raw": ("Freiburg 079", 0.061, 0.044),
}


def one(name: str, seed: int) -> dict[str, object]:
    """Run ``grid-rbpf`` on one log in this process; its scores, times and memory."""
    data = load_dataset(name, data_root=find_data_root())
    cpu, wall = time.process_time(), time.perf_counter()
    result = run("grid-rbpf", data, seed=seed)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    rel = relation_errors(result.times, result.poses, data.truth.relations)
    d = result.output.diagnostics
    return {
        "summary": rel.summary(),
        "translation_mean": rel.translation_mean,
        "cpu": cpu,
        "wall": wall,
        "duration": data.events[-1].t - data.events[0].t,
        "updates": d["updates"],
        "recovered": d["recovered"],
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "peak_map_mb": d["maps"]["peak_bytes"] / 2**20,
    }


def main() -> str:
    parser = argparse.ArgumentParser()
    parser.add_argument("logs", nargs="*", default=list(PUBLISHED))
    parser.add_argument("--seeds", type=int, nargs="*", default=[0])
    parser.add_argument("--one", nargs=2, metavar=("NAME", "SEED"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one is not None:  # the child: one log, one seed, a JSON line out
        print(json.dumps(one(args.one[0], int(args.one[1]))))
        return ""
    if find_data_root() is None:
        return "bench_grid_rbpf: skipped (no real data; set SLAMKIT_DATA)"
    load_before = os.getloadavg()[0]
    records, rows = [], []
    for name in args.logs:
        label, pub_mean, pub_std = PUBLISHED[name]
        for seed in args.seeds:
            child = subprocess.run(
                [sys.executable, __file__, "--one", name, str(seed)],
                check=True, capture_output=True, text=True,
            )  # fmt: skip
            r = json.loads(child.stdout.strip().splitlines()[-1])
            records.append(Record(f"{label} (seed {seed}): RBPF, 30 particles", r["wall"],
                                  "real time (the data's duration)", r["duration"]))  # fmt: skip
            rows.append(
                f"| {label} | {seed} | {r['summary']} | {pub_mean:.3f} ± {pub_std:.3f} m | "
                f"{r['updates']} | {r['recovered']} | {r['cpu']:.0f} | {r['wall']:.0f} | "
                f"{r['duration']:.0f} | {r['peak_rss_mb']:.0f} | {r['peak_map_mb']:.1f} |"
            )
            print(rows[-1], flush=True)
    table = "\n".join(
        [
            "| log | seed | RBPF (30 particles), all relations | published RBPF (50 p.) | "
            "updates | recovered matches | CPU [s] | wall [s] | data [s] | peak RSS [MB] | "
            "peak map tiles [MB] |",
            "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|",
            *rows,
        ]
    )
    notes = (
        "Default GridRbpfConfig (30 particles, the Gaussian proposal). Relation errors: mean "
        "± std, translation [m] and rotation [deg], over every relation the run covers. The "
        "published RBPF figures are quoted, not run here. Peak RSS: the child process that "
        "ran the log (data, filter and all); peak map tiles: the float32 log odds of every "
        f"particle's map at their peak. Load average before the run: {load_before:.1f}."
        "\n\n" + table
    )
    return write_results("grid_rbpf", records, notes=notes) + "\n\n" + table


if __name__ == "__main__":
    print(main())
