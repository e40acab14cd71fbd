"""Saved runs as a table, one row a run (as ``evo_res`` tabulates saved results): the headline
metrics for the console, every scalar of ``metrics.json`` for a CSV file.

Values are the numbers ``metrics.json`` holds, not formatted strings: the CSV is for
spreadsheets and pandas (``pd.read_csv(path, index_col="run")``), the console formats them.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from slamkit.errors import InputError
from slamkit.eval.glossary import describe
from slamkit.report.html import HEADLINE, RunPage

__all__ = [
    "ComparisonTable",
    "comparison_table",
    "format_comparison_csv",
    "scalar_metrics",
    "write_comparison_csv",
]

Scalar = float | int | str | bool | None

_FIXED_COLUMNS = ("run", "folder", "estimator", "dataset")


def scalar_metrics(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, Scalar]:
    """Every scalar of ``metrics.json`` by dotted key (``ate.rmse``), in the file's order;
    lists (warnings, per-step series) are left out. ``estimator`` and ``dataset`` are
    columns of their own."""
    out: dict[str, Scalar] = {}
    for key, value in metrics.items():
        if not prefix and key in ("estimator", "dataset"):
            continue
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(scalar_metrics(value, f"{name}."))
        elif value is None or isinstance(value, (bool, int, float, str)):
            out[name] = value
    return out


@dataclass(frozen=True)
class ComparisonTable:
    """Runs as rows. ``labels`` name the runs (their folder names, or the whole paths when
    two folders share a name); ``values[i]`` holds run ``i``'s scalars by dotted key;
    ``keys`` is every key some run has, in the order first met; ``headline`` the
    ``(key, label)`` of the headline metrics (:data:`slamkit.report.html.HEADLINE`) some run
    has."""

    labels: tuple[str, ...]
    pages: tuple[RunPage, ...]
    values: tuple[dict[str, Scalar], ...]
    keys: tuple[str, ...]
    headline: tuple[tuple[str, str], ...]

    def value(self, run: int, key: str) -> Scalar:
        """Run ``run``'s value of ``key`` (None when it has none)."""
        return self.values[run].get(key)


def comparison_table(pages: Sequence[RunPage]) -> ComparisonTable:
    """The table of the runs ``pages`` (:func:`slamkit.report.read_run_folder`)."""
    if not pages:
        raise InputError("compare: expected at least one run folder")
    names = [p.folder.name or str(p.folder) for p in pages]
    labels = names if len(set(names)) == len(names) else [str(p.folder) for p in pages]
    values = tuple(scalar_metrics(p.metrics) for p in pages)
    keys: dict[str, None] = {}
    for v in values:
        keys.update(dict.fromkeys(v))
    headline = tuple((k, describe(k).heading) for k in HEADLINE if k in keys)
    return ComparisonTable(tuple(labels), tuple(pages), values, tuple(keys), headline)


def format_comparison_csv(table: ComparisonTable) -> str:
    """The table as CSV: a header ``run,folder,estimator,dataset,KEY…`` and a line a run;
    numbers as Python writes them (shortest round-trip form), a missing value empty."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([*_FIXED_COLUMNS, *table.keys])
    for i, page in enumerate(table.pages):
        row: list[Scalar] = [table.labels[i], str(page.folder), page.estimator, page.dataset]
        row += ["" if table.value(i, k) is None else table.value(i, k) for k in table.keys]
        writer.writerow(row)
    return buffer.getvalue()


def write_comparison_csv(table: ComparisonTable, path: str | os.PathLike[str]) -> Path:
    """Write :func:`format_comparison_csv` to ``path`` (its folder created); returns it."""
    target = Path(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(f".{target.name}.tmp")
        tmp.write_text(format_comparison_csv(table), encoding="utf-8")
        os.replace(tmp, target)
    except OSError as exc:
        raise InputError(f"{target}: cannot write ({exc.strerror or exc})") from exc
    return target
