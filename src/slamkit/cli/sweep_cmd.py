"""``slamkit sweep …``: Monte Carlo and parameter studies on Dask. The main app adds
:data:`sweep_app` as ``sweep``.

``slamkit sweep SPEC.toml [--scheduler ADDRESS] [--workers N] [--out DIR]`` runs every point
of the spec (:func:`slamkit.sweep.run_sweep`) with a progress bar of done / running / failed
runs (without a terminal, a plain line every 10 s); ``slamkit sweep report DIR`` writes the
summaries (:func:`slamkit.sweep.write_report`).
``sweep SPEC`` is the group's default command (``sweep run SPEC`` spelled out).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.markup import escape
from typer.core import TyperGroup

from slamkit.cli._common import command_group, console, err_console, known_errors, progress_bar

if TYPE_CHECKING:
    from slamkit.sweep import SweepProgress, SweepReport

__all__ = ["sweep_app"]


class DefaultRunGroup(TyperGroup):
    """A group whose first argument, when it is not a subcommand, goes to ``run``."""

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        if args and args[0] not in self.commands and args[0] not in ("--help", "-h"):
            args = ["run", *args]
        return super().parse_args(ctx, args)


sweep_app = command_group(
    cls=DefaultRunGroup,
    help="Sweeps over estimators × data sets × seeds × settings on Dask: "
    "`slamkit sweep SPEC.toml`, then `slamkit sweep report DIR`.",
)


@sweep_app.command("run")
@known_errors
def run_command(
    spec: Annotated[Path, typer.Argument(help="The sweep's spec (TOML; see docs/sweeps.md).")],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Sweep folder: runs/<key>/ and the table.")
    ] = Path("sweep-out"),
    scheduler: Annotated[
        str | None,
        typer.Option(help="A running Dask scheduler's address (tcp://host:8786)."),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(help="Worker processes of the local cluster (default: one per core)."),
    ] = None,
    data_root: Annotated[
        Path | None,
        typer.Option(help="Data folder as seen by the workers (default: their SLAMKIT_DATA)."),
    ] = None,
    retry_failed: Annotated[
        bool, typer.Option(help="Run again the runs recorded as failed.")
    ] = False,
) -> None:
    """Run every point of SPEC not finished before; write OUT/results.parquet and .csv."""
    from slamkit.sweep import load_spec, run_sweep

    sweep = load_spec(spec)  # a bad spec fails here, before a cluster starts
    with _sweep_progress(escape(sweep.name)) as update:
        try:
            result = run_sweep(
                sweep,
                out,
                scheduler=scheduler,
                workers=workers,
                data_root=data_root,
                retry_failed=retry_failed,
                progress=update,
            )
        except KeyboardInterrupt:  # finished runs are kept: say so, not "nothing written"
            err_console.print(
                f"interrupted; the finished runs are in {escape(str(out))} (run again to resume)",
                highlight=False,
            )
            raise typer.Exit(130) from None
    console.print(
        f"{result.total} runs: {result.executed} run now, {result.skipped} finished before, "
        f"{result.failed} failed"
    )
    for row in result.rows:
        if row["status"] != "ok":
            console.print(f"  [red]failed[/] {row['key']}: {escape(str(row['error']))}")
    names = ", ".join(p.name for p in result.files)
    console.print(f"wrote {names} to [bold]{escape(str(result.out_dir))}[/]", soft_wrap=True)


@contextmanager
def _sweep_progress(name: str) -> Iterator[Callable[[SweepProgress], None]]:
    """The sweep's progress on stderr, as an ``update(SweepProgress)``: on a terminal a bar
    of runs done, running and failed; without one (CI, ``nohup``) a plain line every
    :data:`~slamkit.cli.progress.PLAIN_INTERVAL` seconds, as ``slamkit run`` writes."""
    if not err_console.is_terminal:
        with progress_bar(f"sweep {name}", unit="runs", console=err_console) as plain:

            def update_plain(p: SweepProgress) -> None:
                plain.note(f"{p.running} running, {p.failed} failed")
                plain(p.done, p.total)

            yield update_plain
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} done"),
        TextColumn("{task.fields[running]} running, {task.fields[failed]} failed"),
        TimeElapsedColumn(),
        console=err_console,
        transient=True,
    ) as bar:
        task = bar.add_task(name, total=None, running=0, failed=0)

        def update(p: SweepProgress) -> None:
            bar.update(task, completed=p.done, total=p.total, running=p.running, failed=p.failed)

        yield update


def _print_report(report: SweepReport) -> None:
    from rich.table import Table

    console.print(f"{report.runs} runs: {report.ok} ok, {report.failed} failed")
    if report.consistency:
        table = Table("estimator", "data set", "settings", "seeds", "mean NEES", "band", "NIS/dof")
        for c in report.consistency:
            settings = ", ".join(f"{k}={v}" for k, v in c.settings.items()) or "-"
            band = "-" if c.nees_band is None else f"{c.nees_band[0]:.2f}-{c.nees_band[1]:.2f}"
            table.add_row(
                c.estimator,
                c.dataset,
                escape(settings),
                str(c.runs),
                "-" if c.nees_mean is None else f"{c.nees_mean:.3f}",
                band,
                "-" if c.nis_per_dof is None else f"{c.nis_per_dof:.3f}",
            )
        console.print(table)
    if report.best:
        table = Table("estimator", "data set", "metric", "best settings", "mean")
        for b in report.best:
            settings = ", ".join(f"{k}={v}" for k, v in b.settings.items()) or "-"
            table.add_row(b.estimator, b.dataset, b.metric, escape(settings), f"{b.mean:.4g}")
        console.print(table)


@sweep_app.command("report")
@known_errors
def report_command(
    folder: Annotated[Path, typer.Argument(help="A sweep folder (the --out of a sweep).")],
    metric: Annotated[
        str | None,
        typer.Option(help="Column to rank settings by (default: GPS, relation or ATE error)."),
    ] = None,
    plots: Annotated[bool, typer.Option(help="Write the metric-against-setting PNGs.")] = True,
) -> None:
    """Summarise FOLDER's table: NEES/NIS over seeds with χ² bands, best settings per data
    set, failures, plots; written to FOLDER/report/."""
    from slamkit.sweep import write_report

    report = write_report(folder, metric=metric, plots=plots)
    _print_report(report)
    console.print(
        f"wrote {', '.join(report.files)} to [bold]{escape(str(folder / 'report'))}[/]",
        soft_wrap=True,
    )
