"""Graph-based laser SLAM (``graph-slam``) on the raw Freiburg logs (Intel, ACES, Freiburg
079), scored by the relation metric, mean ± std of the translational [m] and rotational
[deg] errors over all relations, with the whole-log wall time.

Published (Kümmerle et al., Autonomous Robots 27(4), 2009; ``DATA.md``), translational:
graph mapping Intel 0.031, ACES 0.044, Freiburg 079 0.056 m; Cartographer (Hess et al.,
ICRA 2016) 0.0229 / 0.0375 / 0.0452 m and 0.45 / 0.37 / 0.54°. Needs ``SLAMKIT_DATA``.

    python benchmarks/bench_laser_graph.py [intel-raw aces-raw fr079-raw] [--seconds S]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from slamkit.datasets import load_dataset
from slamkit.eval.relations import relation_errors
from slamkit.pipeline import run

PUBLISHED = {"intel-raw": 0.031, "aces-raw": 0.044, "fr079-raw": 0.056}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("logs", nargs="*", default=list(PUBLISHED))
    parser.add_argument("--seconds", type=float, default=None, help="only the first S seconds")
    args = parser.parse_args()
    for name in args.logs:
        data = load_dataset(name)
        if args.seconds is not None:
            t0 = data.events[0].t
            events = tuple(e for e in data.events if e.t <= t0 + args.seconds)
            data = dataclasses.replace(data, events=events)
        tic = time.perf_counter()
        result = run("graph-slam", data, seed=0)
        wall = time.perf_counter() - tic
        rel = relation_errors(result.times, result.poses, data.truth.relations)
        d = result.output.diagnostics
        print(
            f"{name}: {rel.translation_mean:.3f} ± {rel.translation_std:.3f} m, "
            f"{rel.rotation_mean_deg:.2f} ± {rel.rotation_std_deg:.2f} deg over {rel.count} "
            f"relations (published graph mapping {PUBLISHED.get(name, float('nan'))} m); "
            f"wall {wall:.0f} s; keyframes {d['keyframes']}, closures {d['loops_kept']}, "
            f"rejected {d['loops_rejected']}, unmatched {d['unmatched']}, "
            f"optimisation {d['optimization_seconds']:.1f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()
