"""Run the benchmarks and print their tables.

Usage (from the repository root, with slamkit installed, e.g. ``pip install -e .``)::

    python benchmarks/run.py            # every benchmarks/bench_*.py
    python benchmarks/run.py se2 motion # only bench_se2.py and bench_motion.py

Each module's ``main()`` writes ``benchmarks/results/<name>.json`` and ``.md`` and returns the
markdown, which is printed here.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def available() -> list[str]:
    """Module names of every benchmark, e.g. ``["bench_motion", "bench_se2"]``."""
    return sorted(p.stem for p in HERE.glob("bench_*.py"))


def main(argv: list[str] | None = None) -> int:
    names = sys.argv[1:] if argv is None else argv
    known = available()
    modules = [n if n.startswith("bench_") else f"bench_{n}" for n in names] or known
    unknown = [m for m in modules if m not in known]
    if unknown:
        print(
            f"unknown benchmark(s) {', '.join(unknown)}; known: {', '.join(known)}", file=sys.stderr
        )
        return 2
    for module_name in modules:
        # This script's folder is on sys.path because Python runs it as a script.
        module = importlib.import_module(module_name)
        print(module.main())
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
