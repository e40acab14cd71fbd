"""``compare_job``: one page showing several runs' output folders side by side;
``compare_runs``: the page, the runs as a table (``evo_res``-like) and, on request, its CSV."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from slamkit.errors import InputError, SlamkitError
from slamkit.report import (
    ComparisonTable,
    RunPage,
    comparison_table,
    read_run_folder,
    write_compare_page,
    write_comparison_csv,
)

__all__ = ["CompareReport", "compare_job", "compare_runs", "describe_run"]


def describe_run(page: RunPage) -> RunPage:
    """``page`` with the descriptions of its estimator and data set from the registries
    (left empty for names they do not know, such as a data set read from a file)."""
    from slamkit.datasets.registry import get_dataset_entry
    from slamkit.pipeline import get_estimator_entry

    est, ds = page.estimator_description, page.dataset_description
    with contextlib.suppress(SlamkitError):
        est = est or get_estimator_entry(page.estimator).description
    with contextlib.suppress(SlamkitError):
        ds = ds or get_dataset_entry(page.dataset).description
    return replace(page, estimator_description=est, dataset_description=ds)


def compare_job(folders: Sequence[str | os.PathLike[str]], out_dir: str | os.PathLike[str]) -> Path:
    """Write ``compare.html`` into ``out_dir``: the runs written to ``folders`` (by
    ``slamkit run``) side by side — a metrics table with a column per run and their figures.
    Returns the page's path. Raises :class:`~slamkit.errors.InputError` for a folder that is
    not a run's output folder."""
    if len(folders) < 1:
        raise InputError("compare: expected at least one run folder")
    pages = [describe_run(read_run_folder(f)) for f in folders]
    return write_compare_page(pages, out_dir)


@dataclass(frozen=True)
class CompareReport:
    """What :func:`compare_runs` wrote: the page, the table, the CSV file (None: not asked)."""

    page: Path
    table: ComparisonTable
    csv: Path | None


def compare_runs(
    folders: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    *,
    csv: str | os.PathLike[str] | None = None,
) -> CompareReport:
    """:func:`compare_job`'s page, the runs as a :class:`~slamkit.report.ComparisonTable`
    (a row a run) and, with ``csv``, that table written as CSV (every scalar of each
    ``metrics.json``). Every folder is read before anything is written."""
    if len(folders) < 1:
        raise InputError("compare: expected at least one run folder")
    pages = [describe_run(read_run_folder(f)) for f in folders]
    table = comparison_table(pages)
    written = None if csv is None else write_comparison_csv(table, csv)
    return CompareReport(write_compare_page(pages, out_dir), table, written)
