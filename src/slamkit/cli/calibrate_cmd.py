"""``slamkit calibrate --data NAME|PATH``: the odometry's systematic errors, the laser's
mounting and the odometry noise learned from the data set itself
(:mod:`slamkit.app.calibration`).

Parses the options, calls :func:`slamkit.app.calibration.calibration_job` and prints each
value with its standard deviation. Known errors become one red line and exit code 1. Heavy
imports happen inside the command.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.table import Table

from slamkit.cli._common import DataRootOption, console, known_errors, output_folder, progress_bar

if TYPE_CHECKING:
    from slamkit.calibration import CalibrationResult

__all__ = ["calibrate_command"]


def _table(result: CalibrationResult) -> Table:
    table = Table(show_header=True, header_style="bold")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_column("± 1σ", justify="right")
    fit = result.systematic
    std = fit.stds
    er, ser, eb, seb = fit.wheel_errors()

    def add(name: str, value: float, sigma: float, fmt: str) -> None:
        table.add_row(escape(name), format(value, fmt), format(sigma, fmt))

    add("translation scale (true / reported)", fit.translation_scale, std[0], ".4f")
    add("rotation scale (true / reported)", fit.rotation_scale, std[1], ".4f")
    add("wheel-radius error [%]", 100 * er, 100 * ser, ".2f")
    add("wheel-base error [%]", 100 * eb, 100 * seb, ".2f")
    if fit.fit_mounting:
        add("laser mounting x [cm]", 100 * fit.mounting[0], 100 * std[2], ".2f")
        add("laser mounting y [cm]", 100 * fit.mounting[1], 100 * std[3], ".2f")
        add("laser mounting yaw [deg]", math.degrees(fit.mounting[2]), math.degrees(std[4]), ".2f")
    step = result.noise["per_step"]
    add("noise per step: rotation [deg]", math.degrees(step.values[0]),
        math.degrees(step.stds[0]), ".3f")  # fmt: skip
    add("noise per step: translation [cm]", 100 * step.values[1], 100 * step.stds[1], ".3f")
    dist = result.noise["per_distance"]
    for name, value, sigma in zip(dist.names, dist.values, dist.stds, strict=True):
        add(f"noise {name}", value, sigma, ".4f")
    return table


@known_errors
def calibrate_command(
    data: Annotated[str, typer.Option(help="A data set's name or a log's path.")],
    min_distance: Annotated[
        float, typer.Option(help="Keyframe spacing by the wheels' travel, in metres.")
    ] = 0.5,
    fit_mounting: Annotated[
        bool, typer.Option(help="Estimate the laser's mounting (else the data set's).")
    ] = True,
    seed: Annotated[int, typer.Option(help="Seed of a simulated data set.")] = 0,
    out: Annotated[
        Path | None,
        typer.Option(
            help="Output folder (default: a fresh results/calibrate-DATA).", show_default=False
        ),
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing output folder.")] = False,
    data_root: DataRootOption = None,
) -> None:
    """Learn the odometry's wheel-radius and wheel-base errors, the laser's mounting and the
    odometry noise from the laser's own relative motions; write calibration.json and a
    run_config.json that feeds the learned noise back."""
    from slamkit.app.calibration import CalibrationRequest, calibration_job
    from slamkit.calibration import CalibrationSettings
    from slamkit.datasets.files import data_label

    target = output_folder(out, f"calibrate-{data_label(data)}")
    request = CalibrationRequest(
        data=data,
        out_dir=target,
        settings=CalibrationSettings(min_distance=min_distance, fit_mounting=fit_mounting),
        seed=seed,
        overwrite=overwrite,
        data_root=data_root,
    )
    with progress_bar("matching keyframe scans", unit="pairs") as bar:
        report = calibration_job(request, bar)
    r = report.result
    console.print(
        f"{r.pairs} scan pairs matched of {r.keyframes - 1} "
        f"({r.systematic.trimmed} trimmed as outliers; dropped: {r.dropped or 'none'})"
    )
    console.print(_table(r))
    if not report.fed_back:
        console.print("the data set's loader takes no noise options: run_config.json keeps its own")
    console.print(
        f"wrote {', '.join(report.files)} to [bold]{escape(str(report.out_dir))}[/]",
        soft_wrap=True,
    )
