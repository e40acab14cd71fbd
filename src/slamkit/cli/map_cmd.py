"""``slamkit map …``: maps with known poses. The main app adds :data:`map_app` as ``map``.

``slamkit map occupancy --data intel --resolution 0.05 --out DIR`` parses its options, calls
:func:`slamkit.app.mapping.occupancy_map_job` and prints the quality numbers. Known errors
(:class:`~slamkit.errors.SlamkitError`) become one red line and exit code 1. Heavy imports
happen inside the command. Help strings go through :func:`rich.markup.escape`: typer renders
them as rich markup, which would swallow ``[m]`` or ``[mapping]`` as unknown tags.

The command's usable range defaults to :data:`DEFAULT_MAX_RANGE` (30 m), not the sensor's.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

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
)

__all__ = ["DEFAULT_MAX_RANGE", "map_app"]

DEFAULT_MAX_RANGE = 30.0  # = slamkit.app.mapping.USABLE_RANGE (run occupancy-mapping uses it)
"""[m] The command's usable range r_max unless ``--max-range`` or the config file's
``[mapping.model] max_range`` says otherwise (``--max-range sensor``: the sensor's own).

Readings at or beyond r_max only clear free space up to r_max (the inverse model), so with
the CARMEN logs' 80 m the grid fills with long free rays through doors and windows. Measured
at 5 cm (grid cells; free area; the part of it inside the box of the occupied cells):

* Intel: 3497 × 3628 cells (96.2 % unknown), 1163 m², 583 m² — at 30 m: 1607 × 1667,
  729 m², 581 m²;
* Freiburg 079: 3540 × 3917, 12,191 m², 765 m² (6 %) — at 30 m: 1492 × 1871, 3301 m²,
  738 m² (the rest is the starburst of its 36,004 no-return readings, now 30 m long).

Returns beyond 30 m are rare (Intel none, Freiburg 0.10 %, ACES 0.68 % of the returns); they
become max-range readings. The library's :class:`~slamkit.mapping.InverseSensorModel` keeps
the sensor's range as its default (``max_range=None``)."""


map_app = command_group(
    help="Maps with known poses (occupancy grids).",
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
    data: Annotated[
        str | None,
        typer.Option(
            "--data",
            "-d",
            metavar="NAME|PATH",
            help=escape(
                "Data set name or laser log (default: the config file's [dataset], else "
                "rooms-laser; a different one in both is an error)."
            ),
            show_default=False,
        ),
    ] = None,
    resolution: Annotated[
        float | None,
        typer.Option(help=escape("Cell size [m] (default: the config file's, else 0.05).")),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            help="Output folder (default: a fresh results/map-DATA, numbered when taken)."
        ),
    ] = None,
    config: Annotated[
        Path | None,
        typer.Option(help=escape("TOML/JSON file with [mapping] and [dataset] tables and a seed.")),
    ] = None,
    set_: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar="KEY=VALUE",
            help="Override one setting: KEY dotted into sections (model.alpha=0.2), "
            "dataset.KEY for a data set option, seed=N; repeatable.",
            show_default=False,
        ),
    ] = None,
    max_range: Annotated[
        str | None,
        typer.Option(
            help=escape(
                f"Usable range r_max of the laser [m], or 'sensor' for the sensor's own max "
                f"range. Readings at or beyond r_max only clear free space up to r_max. "
                f"Default {DEFAULT_MAX_RANGE:g} m (unless the config file sets "
                f"[mapping.model] max_range): with the 80 m of the CARMEN logs, rays through "
                f"doors and windows fill the grid with free space outside the building."
            ),
            metavar="METRES|sensor",
        ),
    ] = None,
    method: Annotated[
        str | None,
        typer.Option(
            metavar="ray|cell",
            help="Update path: 'ray' (Bresenham, default) or 'cell' (per-cell model).",
        ),
    ] = None,
    poses: Annotated[
        str | None,
        typer.Option(
            metavar="truth|odometry|FILE.tum",
            help="Known poses: 'truth' (default), 'odometry' (logs without truth), or a TUM "
            "trajectory file such as a run's trajectory.tum (interpolated to the scan stamps; "
            "scans outside its time span are dropped and counted).",
        ),
    ] = None,
    seed: Annotated[int | None, typer.Option(help="Seed (simulated data, odometry noise).")] = None,
    data_root: DataRootOption = None,
    agreement: Annotated[
        bool, typer.Option(help="Also map the even and the odd scans and compare them.")
    ] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing output folder.")] = False,
) -> None:
    """Occupancy grid of a laser data set from its known (true) poses; writes map.png,
    map.pgm + map.yaml (ROS map_server), quality.json and config.json."""
    _occupancy(
        data, resolution, out, config, max_range, method, poses, seed, data_root, agreement,
        overwrite, set_ or [],
    )  # fmt: skip


def _usable_range(value: str | None) -> float | None:
    """``--max-range``: metres, ``sensor`` (None: the sensor's), or the default."""
    from slamkit.errors import ConfigError

    if value is None:
        return DEFAULT_MAX_RANGE
    if value.strip().lower() == "sensor":
        return None
    try:
        metres = float(value)
    except ValueError:
        metres = math.nan
    if not (math.isfinite(metres) and metres > 0):
        raise ConfigError(f"--max-range: expected metres > 0 or 'sensor', got {value!r}")
    return metres


def _occupancy(
    data: str | None,
    resolution: float | None,
    out: Path | None,
    config: Path | None,
    max_range: str | None,
    method: str | None,
    poses: str | None,
    seed: int | None,
    data_root: Path | None,
    agreement: bool,
    overwrite: bool,
    overrides: list[str] | None = None,
) -> None:
    from slamkit.app.mapping import occupancy_map_job
    from slamkit.app.runconfig import apply_overrides, read_run_config, resolve_data
    from slamkit.datasets.files import data_label
    from slamkit.errors import ConfigError

    cfg = apply_overrides(read_run_config(config, "mapping"), overrides or [], "mapping")
    mapping, ds_options, cfg_seed = dict(cfg.settings), cfg.dataset_options, cfg.seed
    data = resolve_data(data, cfg, default="rooms-laser", data_root=data_root)
    if method is not None:  # options given on the command line win over the config file
        if method not in ("ray", "cell"):
            raise ConfigError(f"--method: expected 'ray' or 'cell', got {method!r}")
        mapping["method"] = method
    poses_file = None if cfg.poses is None else Path(cfg.poses)
    if poses in ("truth", "odometry"):
        mapping["pose_source"] = poses
        poses_file = None
    elif poses is not None:
        poses_file = Path(poses)
        if not poses_file.is_file():
            raise ConfigError(
                f"--poses: expected 'truth', 'odometry' or a TUM file, got {poses!r} (no such file)"
            )
    model = dict(mapping.get("model", {}))
    if max_range is not None or "max_range" not in model:
        model["max_range"] = _usable_range(max_range)
        mapping["model"] = model
    target = output_folder(out, f"map-{data_label(data)}", config=config)
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
            poses_file=poses_file,
        )
    if report.reading is not None and not report.reading.clean:
        for line in report.reading.lines():
            console.print(escape(line))
    if report.path is not None:
        console.print(escape(report.path.line()))
    console.print(_table(report.quality, report.stats))
    console.print(f"wrote {', '.join(report.files)} to [bold]{report.out_dir}[/]")
