"""Compare two sets of benchmark results case by case: slamkit's own time and the ratio to
the peer, before and after a change.

Run the same benchmark from two checkouts back to back (so that both see the same machine
load), then compare their ``results/`` folders::

    git worktree add /tmp/before <commit>
    (cd /tmp/before && PYTHONPATH=src python benchmarks/run.py filters)
    python benchmarks/run.py filters
    python benchmarks/compare_results.py /tmp/before/benchmarks/results benchmarks/results filters

On a shared machine the ratio moves with the peer's timing as much as with ours; the
before/after of slamkit's own time, measured minutes apart, is the better witness of a change.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def compare(before: Path, after: Path, names: list[str]) -> str:
    """A markdown table: per case, slamkit's time before and after and the ratios."""
    rows = [
        "| benchmark | case | peer | ours before [s] | ours after [s] | after / before "
        "| ratio before | ratio after |",
        "|---|---|---|---:|---:|---:|---:|---:|",
    ]
    for name in names:
        old = json.loads((before / f"{name}.json").read_text(encoding="utf-8"))
        new = json.loads((after / f"{name}.json").read_text(encoding="utf-8"))
        earlier = {(r["case"], r["peer"]): r for r in old["records"]}
        for r in new["records"]:
            o = earlier.get((r["case"], r["peer"]))
            if o is None:
                continue
            rows.append(
                f"| {name} | {r['case']} | {r['peer']} | {o['slamkit_seconds']:.4g} "
                f"| {r['slamkit_seconds']:.4g} | {r['slamkit_seconds'] / o['slamkit_seconds']:.2f} "
                f"| {o['ratio_peer_over_slamkit']:.3g} | {r['ratio_peer_over_slamkit']:.3g} |"
            )
    return "\n".join(rows)


def main(argv: list[str]) -> int:
    if len(argv) < 3:
        print(__doc__)
        return 2
    print(compare(Path(argv[0]), Path(argv[1]), argv[2:]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
