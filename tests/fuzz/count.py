"""Count the fuzz outcomes per reader (the long mode; the table of docs/fuzzing.md).

    PYTHONPATH=src python tests/fuzz/count.py --n 1000 [--seed 0] [--only carmen,g2o] [--show 5]

Prints one row per reader: mutations, typed errors with a line, typed errors without one
(whole-file problems), accepted results (physically plausible), and of those the quirks
(real logs' oddities, read and repaired); then the defects: typed errors not naming the
file, other exceptions, accepted-but-implausible, quirks refused or not reported; and the
first few defects in full.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fuzzcases import DEFECTS, OUTCOMES, cases
from fuzztargets import all_targets


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="mutations per reader")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", default="", help="comma-separated reader names")
    ap.add_argument("--show", type=int, default=5, help="defects shown per reader")
    args = ap.parse_args(argv)
    only = {s for s in args.only.split(",") if s}
    cols = ("mutations", "typed+line", "typed, no line", "typed, file not named",
            "other exception", "accepted", "accepted-but-implausible", "quirk refused",
            "quirks repaired")  # fmt: skip
    print("| reader | " + " | ".join(cols) + " | seconds |")
    print("|---" * (len(cols) + 2) + "|")
    total: Counter[str] = Counter()
    shown: list[str] = []
    for target in all_targets():
        if only and target.name not in only:
            continue
        t0 = time.perf_counter()
        counts: Counter[str] = Counter()
        n_shown = 0
        for outcome in cases(target, args.n, args.seed):
            counts[outcome.kind] += 1
            counts["quirks"] += outcome.kind == "accepted" and outcome.mutation.startswith("quirk")
            if outcome.kind in DEFECTS and n_shown < args.show:
                n_shown += 1
                shown.append(f"{target.name} [{outcome.mutation} of {outcome.file}] "
                             f"{outcome.kind}: {outcome.detail}")  # fmt: skip
        total += counts
        row = [str(args.n)] + [str(counts[k]) for k in (*OUTCOMES, "quirks")]
        print(f"| {target.name} | " + " | ".join(row) + f" | {time.perf_counter() - t0:.1f} |")
        sys.stdout.flush()
    all_counts = [str(total[k]) for k in (*OUTCOMES, "quirks")]
    print(f"| **all** | {sum(total[k] for k in OUTCOMES)} | " + " | ".join(all_counts) + " | |")
    for line in shown:
        print(line)
    return 1 if any(total[k] for k in DEFECTS) else 0


if __name__ == "__main__":
    raise SystemExit(main())
