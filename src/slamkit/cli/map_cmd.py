"""``slamkit map …``: maps with known poses. The main app adds :data:`map_app` as ``map``.

``slamkit map occupancy --data intel --resolution 0.05 --out DIR`` parses its options, calls
:func:`slamkit.app.mapping.occupancy_map_job` and prints the quality numbers. Known errors
(:class:`~slamkit.errors.SlamkitError`) become one red line and exit code 1. Heavy imports
happen inside the command.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from slamkit.cli._common import console, known_errors, progress_bar, split_config

__all__ = ["map_app"]

map_app = typer.Typer(
    help="Maps with known poses (occupancy grids).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _table(quality: dict[str, Any], stats: dict[str, Any]) -> Table:
    table = Table(show_header=True, header_style="bold")
    table.add_column("quantity")
    table.add_column("value", justify="right")

    def add(name: str, value: Any, fmt: str) -> None:
        if value is not None:  # escape: "[m]" would otherwise be read as rich markup
            table.add_row(escape(name), format(value, fmt))

    m = quality["map"]
    add("occupied cells [%]", 100 * m["occupied_fraction"], ".2f")
    add("free cells [%]", 100 * m["free_fraction"], ".2f")
    add("unknown cells [%]", 100 * m["unknown_fraction"], ".2f")
    add("entropy [bits/cell]", m["entropy_bits_per_cell"], ".4f")
    eo = quality.get("even_odd", {})
    agree = eo.get("agreement")
    add("even/odd scan maps agree [%]", None if agree is None else 100 * agree, ".2f")
    truth = quality.get("truth", {}).get("tolerance_1")
    if truth:
        add("occupied precision, ±1 cell", truth["precision"], ".3f")
        add("occupied recall, ±1 cell", truth["recall"], ".3f")
    add("scans used", stats["scans_used"], "d")
    add("cell updates", stats["cell_updates"], ",d")
    add("mapping time [s]", stats["seconds"], ".3f")
    return table


@map_app.command("occupancy")
@known_errors
def occupancy_command(
    data: Annotated[str, typer.Option("--data", "-d", help="Data set name.")] = "rooms-laser",
    resolution: Annotated[float | None, typer.Option(help="Cell size [m].")] = None,
    out: Annotated[
        Path | None, typer.Option(help="Output folder (default results/map-DATA).")
    ] = None,
    config: Annotated[
        Path | None,
        typer.Option(help="TOML/JSON file with [mapping] and [dataset] tables and a seed."),
    ] = None,
    max_range: Annotated[
        float | None, typer.Option(help="Usable range of the laser [m] (default: the sensor's).")
    ] = None,
    method: Annotated[
        str | None,
        typer.Option(help="Update path: 'ray' (Bresenham, default) or 'cell' (per-cell model)."),
    ] = None,
    poses: Annotated[
        str | None,
        typer.Option(help="Known poses: 'truth' (default) or 'odometry' (logs without truth)."),
    ] = None,
    seed: Annotated[int | None, typer.Option(help="Seed (simulated data, odometry noise).")] = None,
    data_root: Annotated[
        Path | None, typer.Option(help="Folder of the real data sets (else $SLAMKIT_DATA).")
    ] = None,
    agreement: Annotated[
        bool, typer.Option(help="Also map the even and the odd scans and compare them.")
    ] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing output folder.")] = False,
) -> None:
    """Occupancy grid of a laser data set from its known (true) poses; writes map.png,
    map.pgm + map.yaml (ROS map_server), quality.json and config.json."""
    _occupancy(
        data, resolution, out, config, max_range, method, poses, seed, data_root, agreement,
        overwrite,
    )  # fmt: skip


def _occupancy(
    data: str,
    resolution: float | None,
    out: Path | None,
    config: Path | None,
    max_range: float | None,
    method: str | None,
    poses: str | None,
    seed: int | None,
    data_root: Path | None,
    agreement: bool,
    overwrite: bool,
) -> None:
    from slamkit.app.mapping import occupancy_map_job
    from slamkit.errors import ConfigError

    mapping, ds_options, cfg_seed = split_config(config, "mapping")
    if method is not None:  # options given on the command line win over the config file
        if method not in ("ray", "cell"):
            raise ConfigError(f"--method: expected 'ray' or 'cell', got {method!r}")
        mapping["method"] = method
    if poses is not None:
        if poses not in ("truth", "odometry"):
            raise ConfigError(f"--poses: expected 'truth' or 'odometry', got {poses!r}")
        mapping["pose_source"] = poses
    if max_range is not None:
        mapping["model"] = {**mapping.get("model", {}), "max_range": max_range}
    target = out if out is not None else Path("results") / f"map-{data}"
    with progress_bar(f"mapping {data}", unit="scans") as progress:
        report = occupancy_map_job(
            data,
            resolution,
            target,
            config=mapping,
            dataset_options=ds_options,
            seed=seed if seed is not None else (cfg_seed if cfg_seed is not None else 0),
            data_root=data_root,
            agreement=agreement,
            overwrite=overwrite,
            progress=progress,
        )
    console.print(_table(report.quality, report.stats))
    console.print(f"wrote {', '.join(report.files)} to [bold]{report.out_dir}[/]")
