"""``occupancy_map_job``: data set → occupancy map with known poses → files and quality.

Writes, into one folder that appears completely or not at all:

* ``map.png`` — one pixel per cell, north up (free white, occupied black, unknown grey);
* ``map_view.png`` — the map as a figure: cropped to the observed cells, axes in metres, a
  scale bar, the poses of the scans used (``plots=False`` leaves it out);
* ``map.pgm`` + ``map.yaml`` — the ROS ``map_server`` pair (:mod:`slamkit.io.rosmap`);
* ``quality.json`` — occupied/free/unknown fractions, entropy, the agreement of the maps of
  the even and the odd scans, precision/recall against the true occupancy where the data set
  has one, and the mapping statistics (cells updated, seconds, grid bytes);
* ``config.json`` — the resolved mapping configuration, the data set and its options, seed,
  and ``poses``, the path mapped along when one was given.

With ``poses_file`` (a TUM trajectory, e.g. a run's ``trajectory.tum``) the known poses are
that path's (:func:`slamkit.mapping.occupancy.dataset_on_path`: interpolated to the scan
stamps, scans outside its span dropped and counted in ``quality.json`` under ``path``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from slamkit.app.runconfig import dataset_table
from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets import Dataset
from slamkit.datasets.files import load_data
from slamkit.datasets.reading import ReadingSummary
from slamkit.io import atomic_folder, read_tum, write_json
from slamkit.io.rosmap import write_ros_map
from slamkit.mapping import (
    OccupancyMappingConfig,
    build_occupancy_map,
    even_odd_agreement,
    map_quality,
    occupied_precision_recall,
)
from slamkit.mapping.occupancy import PathCoverage, dataset_on_path
from slamkit.maps import OccupancyGrid

__all__ = [
    "USABLE_RANGE",
    "USABLE_RANGE_ESTIMATORS",
    "OccupancyMapReport",
    "occupancy_map_job",
    "with_usable_range",
]

USABLE_RANGE = 30.0
"""[m] The laser range the app's occupancy maps use unless the config's ``model.max_range``
says otherwise — ``slamkit map occupancy`` (see its ``DEFAULT_MAX_RANGE`` for the
measurements behind it) and ``slamkit run occupancy-mapping`` alike, so both make the same
map by default. Readings beyond it clear free space up to it only. The library's
:class:`~slamkit.mapping.InverseSensorModel` keeps the sensor's range as its default."""

USABLE_RANGE_ESTIMATORS = ("occupancy-mapping",)
"""Registered estimators whose config gets :data:`USABLE_RANGE` from :func:`run_job
<slamkit.app.jobs.run_job>` (their settings are an
:class:`~slamkit.mapping.OccupancyMappingConfig`)."""


def with_usable_range(
    mapping: Mapping[str, Any], max_range: float | None = USABLE_RANGE
) -> dict[str, Any]:
    """``mapping`` (an :class:`~slamkit.mapping.OccupancyMappingConfig` as a mapping) with
    ``model.max_range`` set to ``max_range`` when it does not set one itself."""
    out = dict(mapping)
    model = out.get("model", {})
    if isinstance(model, Mapping) and "max_range" not in model:
        out["model"] = {**model, "max_range": max_range}
    return out


MAP_FILES = ("config.json", "map.pgm", "map.png", "map.yaml", "map_view.png", "quality.json")


@dataclass(frozen=True)
class OccupancyMapReport:
    """What :func:`occupancy_map_job` wrote and measured."""

    out_dir: Path
    files: tuple[str, ...]
    quality: dict[str, Any]
    stats: dict[str, Any]
    grid: OccupancyGrid
    reading: ReadingSummary | None = None
    """What reading the data file dropped and repaired (None: simulated data)."""
    path: PathCoverage | None = None
    """How the given path covered the scans (None: the data set's own poses)."""


def _config(
    config: Mapping[str, Any] | OccupancyMappingConfig | None, resolution: float | None
) -> OccupancyMappingConfig:
    cfg = (
        config
        if isinstance(config, OccupancyMappingConfig)
        else config_from_mapping(OccupancyMappingConfig, config, "mapping")
    )
    if resolution is not None:  # replace() re-runs the config's checks
        cfg = dataclasses.replace(cfg, resolution=float(resolution))
    return cfg


def occupancy_map_job(
    dataset: str | Dataset,
    resolution: float | None,
    out_dir: str | Path,
    *,
    config: Mapping[str, Any] | OccupancyMappingConfig | None = None,
    dataset_options: Mapping[str, Any] | None = None,
    seed: int = 0,
    data_root: str | Path | None = None,
    agreement: bool = True,
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
    plots: bool = True,
    poses_file: str | Path | None = None,
) -> OccupancyMapReport:
    """Build the occupancy map of ``dataset`` (a registered name, a log's path, or a loaded
    :class:`Dataset`) at ``resolution`` metres (None: the config's) and write the files of
    the module docstring into ``out_dir``.

    ``config`` holds the :class:`~slamkit.mapping.OccupancyMappingConfig` settings (a
    mapping such as a config file's ``[mapping]`` table, or the object); ``resolution``
    overrides its ``resolution``. ``agreement`` also builds the even-scan and odd-scan maps
    (doubling the work) for the agreement number. ``poses_file``: map along this TUM path
    (module docstring) instead of the config's ``pose_source``.
    """
    cfg = _config(config, resolution)  # a bad config fails before the data set is loaded
    path = None
    if poses_file is not None:  # a broken path file fails before the data set is loaded too
        path = read_tum(poses_file)
        cfg = dataclasses.replace(cfg, pose_source="truth")  # the path is the reference
    ds_options = dict(dataset_options or {})
    if isinstance(dataset, Dataset):
        data = dataset
    else:
        data = load_data(dataset, seed=seed, options=ds_options, data_root=data_root)
    coverage = None
    if path is not None:
        data, coverage = dataset_on_path(data, *path, source=str(poses_file))
    result = build_occupancy_map(data, cfg, progress)
    quality: dict[str, Any] = {"map": map_quality(result.grid).as_dict()}
    if agreement:
        quality["even_odd"] = even_odd_agreement(data, cfg, bounds=result.bounds)
    truth = data.truth.occupancy
    if truth is not None:
        quality["truth"] = {
            f"tolerance_{tol}": occupied_precision_recall(result.grid, truth, tolerance_cells=tol)
            for tol in (0, 1, 2)
        }
    stats = result.stats.as_dict()
    stats["grid_shape"] = list(result.grid.shape)
    stats["grid_bytes"] = result.log_odds.nbytes
    stats["bounds"] = None if result.bounds is None else list(result.bounds)
    resolved: dict[str, Any] = {
        "mapping": config_to_dict(cfg),
        "dataset": dataset_table(data, ds_options),
        "seed": seed,
    }
    if coverage is not None:
        quality["path"] = {"file": str(Path(str(poses_file)).resolve()), **coverage.as_dict()}
        resolved["poses"] = quality["path"]["file"]
    from slamkit.viz.maps import save_map_image  # plotting only in the app layer

    with atomic_folder(out_dir, overwrite=overwrite) as tmp:
        save_map_image(result.grid, tmp / "map.png")
        if plots:
            _save_map_view(result.grid, result.poses, data.name, tmp / "map_view.png")
        write_ros_map(result.grid, tmp / "map.pgm", tmp / "map.yaml")
        reading = {} if data.reading is None else {"reading": data.reading.to_dict()}
        write_json(tmp / "quality.json", {**quality, "stats": stats, **reading})
        write_json(tmp / "config.json", resolved)
        files = tuple(sorted(p.name for p in tmp.iterdir()))
    return OccupancyMapReport(
        Path(out_dir), files, quality, stats, result.grid, data.reading, coverage
    )


def _save_map_view(grid: OccupancyGrid, poses: Any, name: str, path: Path) -> None:
    from slamkit.viz import new_figure, save_figure
    from slamkit.viz.maps import plot_map
    from slamkit.viz.report import FIGURE_DPI

    fig = new_figure(figsize=(9.0, 7.0))
    ax = fig.add_subplot()
    plot_map(ax, grid, trajectory=poses, title=f"{name}: occupancy grid ({grid.resolution:g} m)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small")
    save_figure(fig, path, dpi=FIGURE_DPI)
