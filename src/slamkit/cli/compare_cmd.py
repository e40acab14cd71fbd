"""``slamkit compare DIR... --out DIR``: one HTML page with several runs side by side.

Parses the folders, calls :func:`slamkit.app.compare.compare_job` and prints where the page
is. Known errors (a folder that is not a run's output) become one red line and exit code 1.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamkit.cli._common import console, known_errors

__all__ = ["compare_command"]


@known_errors
def compare_command(
    folders: Annotated[
        list[Path], typer.Argument(help="Output folders of `slamkit run` to compare.")
    ],
    out: Annotated[Path, typer.Option(help="Folder to write compare.html into.")] = Path(
        "results/compare"
    ),
) -> None:
    """Write one page (compare.html) with the metrics and figures of several runs side by
    side."""
    from slamkit.app.compare import compare_job

    page = compare_job(folders, out)
    console.print(f"compared {len(folders)} runs: [bold]{page}[/] (open it in a browser)")
