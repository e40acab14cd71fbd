"""``slamkit compare DIR... [--out DIR] [--csv FILE]``: several saved runs side by side — a
table on the console (a row a run, as ``evo_res``), one HTML page, and on request a CSV.

Parses the folders, calls :func:`slamkit.app.compare.compare_runs` and renders its table.
Known errors (a folder that is not a run's output) become one red line and exit code 1.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.table import Table

from slamkit.cli._common import console, known_errors

if TYPE_CHECKING:
    from slamkit.report import ComparisonTable

__all__ = ["compare_command", "comparison_rich_table", "run_legend"]


def _cell(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return "—" if value is None else str(value)


def comparison_rich_table(table: ComparisonTable) -> Table:
    """A row a run, by its number in :func:`run_legend`: its headline metrics (units in the
    headers, numbers at full width), and its estimator and data set when the runs differ in
    them (else they are the title)."""
    estimators = {p.estimator for p in table.pages}
    datasets = {p.dataset for p in table.pages}
    common = [f"{next(iter(s))}" for s in (estimators, datasets) if len(s) == 1]
    out = Table(
        show_header=True,
        header_style="bold",
        title=escape(" on ".join(common)) if len(common) == 2 else None,
    )
    # runs by number (the legend names them), numbers at their full width, headers wrap
    out.add_column("run", justify="right")
    extra = [(name, s) for name, s in (("estimator", estimators), ("data set", datasets))
             if len(s) > 1 or len(common) < 2]  # fmt: skip
    for name, _ in extra:
        out.add_column(name, overflow="fold")
    numbers = [[_cell(table.value(i, key)) for key, _ in table.headline]
               for i in range(len(table.pages))]  # fmt: skip
    for j, (_, label) in enumerate(table.headline):  # escape: "[m]" would be read as markup
        width = max(len(row[j]) for row in numbers)
        out.add_column(escape(label), justify="right", min_width=width)
    for i, page in enumerate(table.pages):
        facts = {"estimator": page.estimator, "data set": page.dataset}
        cells = [escape(facts[name]) for name, _ in extra]
        out.add_row(str(i + 1), *cells, *numbers[i])
    return out


def run_legend(table: ComparisonTable) -> list[str]:
    """``"1  results/ekf"``: the run numbers of :func:`comparison_rich_table` and their folders."""
    return [f"{i + 1:>3}  {page.folder}" for i, page in enumerate(table.pages)]


@known_errors
def compare_command(
    folders: Annotated[
        list[Path], typer.Argument(help="Output folders of `slamkit run` to compare.")
    ],
    out: Annotated[Path, typer.Option(help="Folder to write compare.html into.")] = Path(
        "results/compare"
    ),
    csv: Annotated[
        Path | None,
        typer.Option(
            help="Also write the runs as CSV: a row a run, a column for every number of its "
            "metrics.json (ate.rmse, runtime.total_seconds, …).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Compare saved runs: a table of their headline metrics, one page (compare.html) with
    their metrics and figures side by side, and with --csv every metric as CSV."""
    from slamkit.app.compare import compare_runs

    report = compare_runs(folders, out, csv=csv)
    for line in run_legend(report.table):
        console.print(escape(line), soft_wrap=True, highlight=False)
    console.print(comparison_rich_table(report.table))
    console.print(
        f"compared {len(folders)} runs: [bold]{escape(str(report.page))}[/] (open it in a browser)",
        soft_wrap=True,
    )
    if report.csv is not None:
        console.print(f"wrote [bold]{escape(str(report.csv))}[/]", soft_wrap=True)
