"""Saved runs as a table (``slamkit compare``'s console table and CSV), on hand-made runs."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from slamkit.report import RunPage, comparison_table, format_comparison_csv, scalar_metrics


def _page(folder: str, metrics: dict) -> RunPage:
    return RunPage(folder=Path(folder), estimator="ekf-slam", dataset="five-features",
                   metrics=metrics)  # fmt: skip


def test_scalars_by_dotted_key_without_lists():
    m = {"estimator": "x", "ate": {"rmse": 0.1, "count": 3}, "warnings": ["w"], "seed": 2,
         "landmarks": {"skipped": "no map"}}  # fmt: skip
    assert scalar_metrics(m) == {"ate.rmse": 0.1, "ate.count": 3, "seed": 2,
                                 "landmarks.skipped": "no map"}  # fmt: skip


def test_rows_are_runs_columns_every_key_and_labels_unique():
    a = _page("one/run", {"ate": {"rmse": 0.1 + 0.2}, "runtime": {"total_seconds": 2.5}})
    b = _page("two/run", {"ate": {"rmse": 1e-17}, "final_position_error": 0.25})
    table = comparison_table([a, b])
    assert table.labels == ("one/run", "two/run")  # the same folder name twice: whole paths
    assert table.keys == ("ate.rmse", "runtime.total_seconds", "final_position_error")
    assert [k for k, _ in table.headline] == [
        "ate.rmse", "final_position_error", "runtime.total_seconds"]  # fmt: skip
    rows = list(csv.reader(io.StringIO(format_comparison_csv(table))))
    assert rows[0] == ["run", "folder", "estimator", "dataset", *table.keys]
    assert rows[1][4:] == ["0.30000000000000004", "2.5", ""]  # shortest round-trip numbers
    assert float(rows[2][4]) == 1e-17 and rows[2][5] == "" and rows[2][6] == "0.25"
    assert comparison_table([a, _page("x/other", {})]).labels == ("run", "other")
