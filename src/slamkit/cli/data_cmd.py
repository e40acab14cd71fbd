"""``slamkit data list`` and ``slamkit data fetch``: which data sets are here, and get them.

Each command parses, calls one library function (:func:`slamkit.datasets.fetch.dataset_status`,
:func:`slamkit.datasets.fetch.fetch_dataset`) and renders what it returns.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.table import Table

from slamkit.cli._common import (
    DataRootOption,
    command_group,
    console,
    err_console,
    known_errors,
    progress_bar,
)

if TYPE_CHECKING:
    from slamkit.datasets.fetch import FetchReport

__all__ = ["data_app"]

data_app = command_group("Data sets: simulated scenarios and real-data loaders.")


def _files(n: int) -> str:
    return f"{n} file" if n == 1 else f"{n} files"


def _size(n: int) -> str:
    return f"{n / 1e6:.1f} MB" if n >= 100_000 else f"{n / 1e3:.1f} kB"


@data_app.command("list")
@known_errors
def data_list_command(
    data_root: DataRootOption = None,
    verify: Annotated[
        bool, typer.Option(help="Also check each real data set's files by SHA-256 (slower).")
    ] = False,
) -> None:
    """List the registered data sets and whether each one's files are here."""
    from slamkit.datasets import list_datasets
    from slamkit.datasets.fetch import dataset_status

    table = Table("name", "kind", "available", "files", "description", header_style="bold")
    for e in list_datasets():
        status = dataset_status(e, data_root, verify=verify)
        ok = "yes" if status.available else "[red]no[/]"
        files = status.summary() if status.available else f"[red]{status.summary()}[/]"
        table.add_row(e.name, e.kind, ok, files, e.description)
    console.print(table)
    console.print("a real data set that is not here: `slamkit data fetch NAME` (docs/data.md)")


def _render_fetch(report: FetchReport) -> None:
    for f in report.files:
        if f.action in ("downloaded", "replaced"):
            console.print(f"{f.action} {escape(str(f.path))} ({_size(f.file.size)}, SHA-256 ok)")
    present = sum(f.action == "present" for f in report.files)
    if present:
        console.print(f"{present} of {_files(len(report.files))} already present and verified")
    manual = report.by_hand
    if not manual:
        console.print(
            f"[bold]{report.name}[/]: {_files(len(report.files))} verified under "
            f"[bold]{escape(str(report.root))}[/]"
        )
        return
    console.print(f"[bold]{report.name}[/]: {_files(len(manual))} to get by hand:")
    for f in manual:
        console.print(
            f"  {escape(f.file.path)}: {f.file.size} bytes, SHA-256 {f.file.sha256}",
            soft_wrap=True,
        )
        console.print(f"    put it at   {escape(str(f.path))}", soft_wrap=True)
        origin = f.origin
        if origin is None:
            console.print("    get it from (origin unknown)")
            continue
        console.print(f"    get it from {escape(origin.publisher)}, {origin.url}", soft_wrap=True)
        if origin.packaging:
            console.print(f"    note        {escape(origin.packaging)}", soft_wrap=True)


@data_app.command("fetch")
@known_errors
def data_fetch_command(
    names: Annotated[
        list[str],
        typer.Argument(
            help="Real data set (see `slamkit data list`) or group (corrected-carmen, "
            "posegraph2d, posegraph3d, isam, ...; docs/data.md).",
            show_default=False,
        ),
    ],
    mirror: Annotated[
        str | None,
        typer.Option(
            metavar="URL|FOLDER",
            help="Base URL (http, https, file) or folder laid out like the data folder "
            "(else $SLAMKIT_DATA_MIRROR). Without one, print where to get each file by hand.",
            show_default=False,
        ),
    ] = None,
    data_root: Annotated[
        Path | None,
        typer.Option(
            help="Folder to fetch into (else $SLAMKIT_DATA, else the data folder found).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Download the missing files of data sets from a mirror, check their size and SHA-256,
    and put them under the data folder; files already there and verified are kept."""
    from slamkit.datasets.fetch import fetch_dataset

    manual = 0
    for name in names:
        with progress_bar(f"fetching {name}", unit="bytes", console=err_console) as progress:
            report = fetch_dataset(name, data_root=data_root, mirror=mirror, progress=progress)
        _render_fetch(report)
        manual += len(report.by_hand)
    if manual:
        err_console.print(
            f"{_files(manual)} to get by hand (listed above): no mirror set (--mirror URL or "
            "$SLAMKIT_DATA_MIRROR)",
            highlight=False,
            soft_wrap=True,
        )
        raise typer.Exit(1)
