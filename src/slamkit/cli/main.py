"""``slamkit``: run estimators on data sets, optimise graph files, list data sets, run the demo.

Every command parses its options, calls one library function and renders what it returns.
Known errors (:class:`~slamkit.errors.SlamkitError`) become one red line and exit code 1.
Heavy imports happen inside the commands so ``slamkit --help`` stays fast.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from slamkit.cli._common import console, known_errors, progress_bar, split_config
from slamkit.cli.map_cmd import map_app
from slamkit.cli.optimize_cmd import optimize_command

app = typer.Typer(
    name="slamkit",
    help="Probabilistic robot localization, mapping and SLAM.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
data_app = typer.Typer(help="Data sets: simulated scenarios and real-data loaders.")
app.add_typer(data_app, name="data")
app.add_typer(map_app, name="map")


def _render_metrics(metrics: dict[str, Any]) -> Table:
    table = Table(show_header=True, header_style="bold")
    table.add_column("metric")
    table.add_column("value", justify="right")

    def add(name: str, value: float | str | None, fmt: str) -> None:
        if value is not None:  # escape: "[m]" would otherwise be read as rich markup
            table.add_row(escape(name), format(value, fmt))

    ate = metrics.get("ate", {})
    add("ATE RMSE, SE(2)-aligned [m]", ate.get("rmse"), ".3f")
    add("ATE RMSE, unaligned [m]", metrics.get("ate_unaligned", {}).get("rmse"), ".3f")
    add("heading RMSE, unaligned [deg]", _deg(metrics.get("ate_unaligned", {})), ".2f")
    add("final position error [m]", metrics.get("final_position_error"), ".3f")
    add("mean NEES (3 dof)", metrics.get("nees", {}).get("mean"), ".2f")
    conv = metrics.get("convergence", {})
    add("converged after [s]", conv.get("time_s"), ".1f")
    add("median error after [m]", conv.get("position_error_after", {}).get("median"), ".3f")
    lm = metrics.get("landmarks", {})
    add("landmark RMSE [m]", lm.get("rmse"), ".3f")
    add("landmarks mapped / true", _ratio(lm.get("n_matched"), lm.get("n_missing")), "s")
    add("GPS RMSE, SE(2)-aligned [m]", metrics.get("gps", {}).get("rmse"), ".3f")
    assoc = metrics.get("association", {})
    add("association accuracy", assoc.get("accuracy"), ".4f")
    add("duplicate landmarks", assoc.get("duplicates"), "d")
    add("run time [s]", metrics.get("runtime", {}).get("total_seconds"), ".3f")
    return table


def _ratio(matched: int | None, missing: int | None) -> str | None:
    return None if matched is None or missing is None else f"{matched} / {matched + missing}"


def _deg(ate: dict[str, Any]) -> float | None:
    import math

    v = ate.get("heading_rmse")
    return None if v is None else math.degrees(v)


def _run(
    estimator: str,
    data: str,
    out: Path,
    *,
    config: Path | None,
    seed: int | None,
    data_root: Path | None,
    plots: bool,
    overwrite: bool,
    animate: bool = False,
) -> None:
    from slamkit.app import RunRequest, run_job

    est_cfg, ds_opts, cfg_seed = split_config(config, "estimator")
    request = RunRequest(
        estimator=estimator,
        dataset=data,
        out_dir=out,
        seed=seed if seed is not None else (cfg_seed if cfg_seed is not None else 0),
        estimator_config=est_cfg,
        dataset_options=ds_opts,
        data_root=data_root,
        plots=plots,
        overwrite=overwrite,
        animate=animate,
    )
    with progress_bar(f"{estimator} on {data}") as progress:
        report = run_job(request, progress)
    if report.dataset_settings:
        used = ", ".join(f"{k}={v}" for k, v in report.dataset_settings.items())
        console.print(f"settings measured for {data} (config.json has them all): {used}")
    console.print(_render_metrics(report.metrics))
    console.print(f"wrote {', '.join(report.files)} to [bold]{report.out_dir}[/]")


@app.command("run")
@known_errors
def run_command(
    estimator: Annotated[str, typer.Argument(help="Estimator name (see `slamkit estimators`).")],
    data: Annotated[str, typer.Option("--data", "-d", help="Data set name.")] = "five-features",
    config: Annotated[
        Path | None,
        # "\[" keeps rich markup from swallowing the table names in the help text.
        typer.Option(help=r"TOML/JSON file with \[estimator] and \[dataset] tables and a seed."),
    ] = None,
    seed: Annotated[int | None, typer.Option(help="Seed of the simulator and estimator.")] = None,
    out: Annotated[
        Path | None, typer.Option(help="Output folder (default results/ESTIMATOR-DATA).")
    ] = None,
    data_root: Annotated[
        Path | None, typer.Option(help="Folder of the real data sets (else $SLAMKIT_DATA).")
    ] = None,
    plots: Annotated[bool, typer.Option(help="Write PNG plots.")] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing output folder.")] = False,
    animate: Annotated[
        bool, typer.Option(help="Also write animation.gif: the estimate and its map over time.")
    ] = False,
) -> None:
    """Run ESTIMATOR on a data set; write trajectory, metrics, config and plots."""
    target = out if out is not None else Path("results") / f"{estimator}-{data}"
    _run(
        estimator,
        data,
        target,
        config=config,
        seed=seed,
        data_root=data_root,
        plots=plots,
        overwrite=overwrite,
        animate=animate,
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


app.command("optimize")(optimize_command)


@app.command("estimators")
def estimators_command() -> None:
    """List the registered estimators."""
    from slamkit.pipeline import list_estimators

    table = Table("name", "needs", "description", header_style="bold")
    for e in list_estimators():
        table.add_row(e.name, ", ".join(e.requires), e.description)
    console.print(table)


@data_app.command("list")
@known_errors
def data_list_command(
    data_root: Annotated[
        Path | None, typer.Option(help="Folder of the real data sets (else $SLAMKIT_DATA).")
    ] = None,
) -> None:
    """List the registered data sets and whether each is available here."""
    from slamkit.datasets import dataset_available, list_datasets

    table = Table("name", "kind", "available", "description", header_style="bold")
    for e in list_datasets():
        ok = dataset_available(e, data_root)
        table.add_row(e.name, e.kind, "yes" if ok else "[red]no[/]", e.description)
    console.print(table)


def main() -> None:
    """Entry point of the ``slamkit`` console script."""
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
