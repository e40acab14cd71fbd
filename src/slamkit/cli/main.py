"""``slamkit``: run estimators on data sets, optimise graph files, score trajectory files
against reference relations, list data sets, run the demo.

Every command parses its options, calls one library function and renders what it returns.
Known errors (:class:`~slamkit.errors.SlamkitError`) become one red line and exit code 1.
Heavy imports happen inside the commands so ``slamkit --help`` stays fast.
"""

from __future__ import annotations

import signal
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.table import Table

from slamkit.cli._common import (
    DataRootOption,
    command_group,
    console,
    known_errors,
    output_folder,
    progress_bar,
    terminate,
)
from slamkit.cli.calibrate_cmd import calibrate_command
from slamkit.cli.compare_cmd import compare_command
from slamkit.cli.config_cmd import config_app
from slamkit.cli.data_cmd import data_app
from slamkit.cli.eval_cmd import eval_app
from slamkit.cli.landmark_graph_cmd import landmark_graph_command
from slamkit.cli.map_cmd import map_app
from slamkit.cli.optimize_cmd import optimize_command
from slamkit.cli.sweep_cmd import sweep_app

if TYPE_CHECKING:
    from slamkit.eval.records import RunScores

app = command_group(
    name="slamkit",
    help="Probabilistic robot localization, mapping and SLAM.",
)
app.add_typer(data_app, name="data")
app.add_typer(map_app, name="map")
app.add_typer(eval_app, name="eval")
app.add_typer(sweep_app, name="sweep")
app.add_typer(config_app, name="config")


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            number = version("slamkit")
        except PackageNotFoundError:  # run from a source tree that was never installed
            number = "unknown (not installed)"
        typer.echo(f"slamkit {number}")
        raise typer.Exit


@app.callback()
def main_options(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """Probabilistic robot localization, mapping and SLAM."""


def _render_metrics(scores: RunScores) -> Table:
    """The headline scores of a run by group, labels and units from
    :mod:`slamkit.eval.glossary` (the report page's); those that do not apply are left out."""
    from slamkit.eval.glossary import GROUPS, metric_rows

    table = Table(show_header=True, header_style="bold")
    table.add_column("metric")
    table.add_column("value", justify="right")
    rows = [r for r in metric_rows(scores.as_dict()) if r.info.console]
    for group in GROUPS:
        mine = [r for r in rows if r.info.group == group]
        if not mine:
            continue
        table.add_row(f"[bold]{escape(group)}[/]", "", end_section=False)
        for row in mine:  # escape: "[m]" would otherwise be read as rich markup
            table.add_row("  " + escape(row.info.heading), escape(row.text))
        table.add_section()
    return table


def _run(
    estimator: str,
    data: str | None,
    out: Path | None,
    *,
    config: Path | None,
    seed: int | None,
    data_root: Path | None,
    plots: bool,
    overwrite: bool,
    animate: bool = False,
    preset: str | None = None,
    overrides: list[str] | None = None,
    formats: list[str] | None = None,
    svg: bool = False,
    rerun: str | None = None,
    known_map: Path | None = None,
    mcap: Path | None = None,
) -> None:
    from slamkit.app import RunRequest, run_job
    from slamkit.app.runconfig import apply_overrides, read_run_config, resolve_data
    from slamkit.datasets.files import data_label

    cfg = apply_overrides(read_run_config(config, "estimator"), overrides or [], "estimator")
    data = resolve_data(data, cfg, data_root=data_root)
    seed = seed if seed is not None else cfg.seed
    preset = preset if preset is not None else (cfg.preset or "auto")
    target = output_folder(out, f"{estimator}-{data_label(data)}", config=config)
    request = RunRequest(
        estimator=estimator,
        dataset=data,
        out_dir=target,
        seed=seed if seed is not None else 0,
        estimator_config=cfg.settings,
        dataset_options=cfg.dataset_options,
        data_root=data_root,
        plots=plots,
        overwrite=overwrite,
        animate=animate,
        preset=None if preset == "none" else preset,
        formats=tuple(f for f in (formats or []) if f != "tum"),
        svg=svg,
        rerun=rerun,
        known_map=known_map if known_map is not None else _config_map(cfg.known_map),
        mcap=mcap,
    )
    with progress_bar(f"{estimator} on {data}") as progress:
        report = run_job(request, progress, progress.stage, progress.counting)
    if report.preset_settings:
        used = ", ".join(f"{k}={v}" for k, v in report.preset_settings.items())
        console.print(f"preset {report.preset} (config.json has every setting): {used}")
    if report.reading is not None and not report.reading.clean:
        for line in report.reading.lines():
            console.print(escape(line))
    for note in report.map_notes:
        console.print(f"map: {escape(note)}")
    console.print(_render_metrics(report.scores))
    for warning in report.scores.warnings:  # the consistency monitor (slamkit.eval.monitor)
        console.print(f"[bold yellow]warning:[/] {escape(warning.message)}")
    judged = report.scores.verdict
    colour = "green" if judged.consistent else "yellow"
    console.print(f"[bold {colour}]verdict:[/] {escape(judged.line)}")
    console.print(f"wrote {', '.join(report.files)} to [bold]{report.out_dir}[/]")
    if "report.html" in report.files:
        console.print(f"report: [bold]{report.out_dir / 'report.html'}[/] (open it in a browser)")


def _config_map(text: str | None) -> Path | None:
    return None if text is None else Path(text)


@app.command("run")
@known_errors
def run_command(
    estimator: Annotated[str, typer.Argument(help="Estimator name (see `slamkit estimators`).")],
    data: Annotated[
        str | None,
        typer.Option(
            "--data",
            "-d",
            metavar="NAME|PATH",
            help="Data set name (see `slamkit data list`), or the path of a laser log: ROS 1 "
            ".bag, ROS 2 bag folder, .db3, .mcap, CARMEN .clf/.log/.log.gz (reader options in "
            r"the config file's \[dataset] table; a relative path not found here is looked up "
            r"under the data folder). Default: the config file's \[dataset] name or path, "
            "else five-features.",
            show_default=False,
        ),
    ] = None,
    config: Annotated[
        Path | None,
        # "\[" keeps rich markup from swallowing the table names in the help text.
        typer.Option(
            help=r"TOML/JSON file with \[estimator] and \[dataset] tables, seed and preset "
            "(a run's config.json re-runs it; `slamkit config show ESTIMATOR` prints one).",
            show_default=False,
        ),
    ] = None,
    set_: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar="KEY=VALUE",
            help="Override one setting: KEY=VALUE, KEY dotted into sections (kld.epsilon=0.1), "
            "dataset.KEY for a data set option, seed=N; repeatable.",
            show_default=False,
        ),
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option(help="Seed of the simulator and estimator (default 0).", show_default=False),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            help="Output folder (default: a fresh results/ESTIMATOR-DATA, numbered -2, -3, … "
            "when taken).",
            show_default=False,
        ),
    ] = None,
    data_root: DataRootOption = None,
    plots: Annotated[bool, typer.Option(help="Write PNG plots.")] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing output folder.")] = False,
    animate: Annotated[
        bool, typer.Option(help="Also write animation.gif: the estimate and its map over time.")
    ] = False,
    formats: Annotated[
        list[str] | None,
        typer.Option(
            "--format",
            metavar="kitti",
            help="Also write the trajectory in this format: kitti (trajectory.kitti + "
            "times.txt); tum is always written. Repeatable.",
            show_default=False,
        ),
    ] = None,
    preset: Annotated[
        str | None,
        typer.Option(
            metavar="auto|none|NAME",
            help="Settings measured for this estimator on this data set: 'auto' (the matching "
            "preset, if any; the default), 'none', or a preset's name.",
            show_default=False,
        ),
    ] = None,
    svg: Annotated[bool, typer.Option(help="Also write every figure as SVG.")] = False,
    rerun: Annotated[
        str | None,
        typer.Option(
            metavar="FILE.rrd|spawn",
            help=escape(
                "Also record the run for the rerun viewer: a .rrd file (relative: inside the "
                "output folder) or 'spawn' a viewer. Needs pip install 'slamkit[rerun]'."
            ),
            show_default=False,
        ),
    ] = None,
    known_map: Annotated[
        Path | None,
        typer.Option(
            "--map",
            metavar="MAP.yaml",
            help="Localize in this saved ROS map_server map (YAML + PGM, as `slamkit map "
            "occupancy` and every mapping run write them); mcl only. Without a prior pose in "
            "the data (or with --set start.uniform=true) the particles start spread over the "
            "map's free space (global localization).",
            show_default=False,
        ),
    ] = None,
    mcap: Annotated[
        Path | None,
        typer.Option(
            metavar="FILE.mcap",
            help=escape(
                "Also write the run for Foxglove: scans, path, pose graph with its loop "
                "closures, map (relative: inside the output folder). Needs pip install "
                "'slamkit[mcap]'."
            ),
            show_default=False,
        ),
    ] = None,
) -> None:
    """Run ESTIMATOR on a data set; write trajectory, metrics, config, plots and report.html."""
    _run(
        estimator,
        data,
        out,
        config=config,
        seed=seed,
        data_root=data_root,
        plots=plots,
        overwrite=overwrite,
        animate=animate,
        preset=preset,
        overrides=set_,
        formats=formats,
        svg=svg,
        rerun=rerun,
        known_map=known_map,
        mcap=mcap,
    )


@app.command("demo")
@known_errors
def demo_command(
    out: Annotated[Path, typer.Option(help="Output folder.")] = Path("results/demo"),
    seed: Annotated[int, typer.Option(help="Seed of the simulated world.")] = 0,
) -> None:
    """Run the main job on the built-in simulated world and say where the results are."""
    from slamkit.app.demo import DEMO_DATASET, DEMO_ESTIMATOR

    console.print(
        f"slamkit demo: [bold]{DEMO_ESTIMATOR}[/] on the simulated [bold]{DEMO_DATASET}[/]"
    )
    _run(
        DEMO_ESTIMATOR,
        DEMO_DATASET,
        out,
        config=None,
        seed=seed,
        data_root=None,
        plots=True,
        overwrite=True,
    )
    from slamkit.app.demo import DEMO_LOOK_AT

    console.print("[bold]where to look[/] (the report page shows them all):")
    for name, what in DEMO_LOOK_AT:
        if (out / name).exists():
            console.print(f"  {out / name}: {what}")


app.command("optimize")(optimize_command)
app.command("compare")(compare_command)
app.command("landmark-graph")(landmark_graph_command)
app.command("calibrate")(calibrate_command)


@app.command("estimators")
def estimators_command() -> None:
    """List the registered estimators."""
    from slamkit.pipeline import list_estimators

    table = Table("name", "needs", "description", header_style="bold")
    for e in list_estimators():
        table.add_row(e.name, ", ".join(e.requires), e.description)
    console.print(table)


def main() -> None:
    """Entry point of the ``slamkit`` console script (SIGTERM unwinds like Ctrl-C)."""
    signal.signal(signal.SIGTERM, terminate)
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
