"""Shared helpers of the benchmark scripts: timing and result files.

A benchmark module ``benchmarks/bench_<name>.py`` defines ``main() -> str`` which times
slamkit against a peer *in the same run*, calls :func:`write_results` and returns the markdown
table it wrote. ``benchmarks/run.py`` runs every such module. In short::

    from _common import Record, best_of, write_results

    def main() -> str:
        t_ours, ours = best_of(lambda: our_function(data))
        t_peer, theirs = best_of(lambda: peer_function(data))
        check_same_answer(ours, theirs)  # a benchmark of a wrong answer is worthless
        records = [Record("case name", t_ours, "peer name", t_peer)]
        return write_results("<name>", records, notes="problem size, caveats")

Results go to ``benchmarks/results/<name>.json`` (machine info plus every record) and
``benchmarks/results/<name>.md`` (a short table); both are meant to be committed.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

__all__ = ["RESULTS_DIR", "Record", "best_of", "format_table", "machine_info", "write_results"]

RESULTS_DIR = Path(__file__).resolve().parent / "results"

T = TypeVar("T")


def best_of(fn: Callable[[], T], repeats: int = 5) -> tuple[float, T]:
    """Call ``fn()`` ``repeats`` times; return the fastest wall-clock time in seconds
    (``time.perf_counter``) and the value of the last call, so the caller can check answers.

    The minimum is the least noisy estimate of the cost itself: other processes and caches
    only ever add time.
    """
    if repeats < 1:
        raise ValueError(f"repeats: expected >= 1, got {repeats}")
    best = float("inf")
    value: T
    for _ in range(repeats):
        start = time.perf_counter()
        value = fn()
        best = min(best, time.perf_counter() - start)
    return best, value


@dataclass(frozen=True)
class Record:
    """One benchmark case: slamkit's time and a peer's time on the same input, in seconds."""

    case: str
    slamkit_seconds: float
    peer: str
    peer_seconds: float

    @property
    def ratio(self) -> float:
        """``peer_seconds / slamkit_seconds``: above 1 means slamkit is faster."""
        return self.peer_seconds / self.slamkit_seconds


def _version_of(package: str) -> str | None:
    try:
        return version(package)
    except PackageNotFoundError:
        return None


def machine_info() -> dict[str, Any]:
    """Python, NumPy and slamkit versions, platform and CPU count of this run."""
    return {
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "slamkit": _version_of("slamkit"),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": platform.processor() or None,
        "cpu_count": os.cpu_count(),
    }


def format_table(records: Sequence[Record]) -> str:
    """A markdown table with one row per record."""
    lines = [
        "| case | slamkit [s] | peer | peer [s] | peer / slamkit |",
        "|---|---:|---|---:|---:|",
    ]
    for r in records:
        lines.append(
            f"| {r.case} | {r.slamkit_seconds:.4g} | {r.peer} | {r.peer_seconds:.4g} "
            f"| {r.ratio:.3g}× |"
        )
    return "\n".join(lines)


def write_results(
    name: str, records: Sequence[Record], notes: str = "", results_dir: Path | None = None
) -> str:
    """Write ``<results_dir>/<name>.json`` and ``<name>.md``; return the markdown text.

    ``results_dir`` defaults to ``benchmarks/results``; ``notes`` (problem sizes, what is and is
    not timed, caveats) is stored in both files.
    """
    out_dir = RESULTS_DIR if results_dir is None else Path(results_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    machine = machine_info()
    created = datetime.now(UTC).isoformat(timespec="seconds")
    payload = {
        "benchmark": name,
        "created_utc": created,
        "machine": machine,
        "notes": notes,
        "records": [
            {
                "case": r.case,
                "slamkit_seconds": r.slamkit_seconds,
                "peer": r.peer,
                "peer_seconds": r.peer_seconds,
                "ratio_peer_over_slamkit": r.ratio,
            }
            for r in records
        ],
    }
    (out_dir / f"{name}.json").write_text(
        json.dumps(payload, indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
    )
    markdown = "\n".join(
        [
            f"## Benchmark `{name}`",
            "",
            f"{created}; Python {machine['python']}, NumPy {machine['numpy']}, "
            f"{machine['platform']}, {machine['cpu_count']} CPUs.",
            "",
            format_table(records),
            "",
            *([notes, ""] if notes else []),
        ]
    )
    (out_dir / f"{name}.md").write_text(markdown, encoding="utf-8")
    return markdown
