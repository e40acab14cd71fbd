"""Localization data sets in maps that slamkit builds itself.

A corrected laser log (CARMEN) comes with a good trajectory but with no map. This module
builds the occupancy grid from the corrected poses with :func:`~slamkit.mapping.build_occupancy_map`
and returns the log as a *localization* data set: the grid is the data set's ``known_grid``,
the events are the log's odometry (derived from the corrected poses with known added noise,
see :mod:`slamkit.datasets.carmen`) and scans, the corrected trajectory stays the ground
truth, and there is no prior pose unless asked for (global localization). Registered as
``intel-mcl``, so that ``slamkit run mcl --data intel-mcl`` localizes in the Intel map.

Why a registered data set rather than only a library function: every estimator that needs a
``known_grid`` then runs on it unchanged, through the same CLI, result folders and
evaluation as any other data set. The steps are public functions
(:func:`build_localization_map`, :func:`crop_to_occupied`, :func:`localization_dataset`) so
that a caller can build the map once and attach it to many odometry draws (tests over seeds).

Why here and not in :mod:`slamkit.datasets`: the data model and the loaders sit *below*
mapping in the layers (``docs/architecture.md``); a builder that runs the mapper belongs to
the mapping layer, which may import both.

**The map** (:func:`build_localization_map`): the default
:class:`~slamkit.mapping.OccupancyMappingConfig` (Bresenham rays, α/β inverse model) at
``resolution`` (5 cm) from the true poses, then cut to the box of its occupied cells grown by
``crop_margin``. The cut matters: in the Intel log, rays that leave the building through
windows and doors reach 80 m, so the grid sized to the data spans 181 m × 175 m (12.7 M cells,
100 MB per float array, 96 % of it unknown) while the walls lie within 39 m × 36 m; cut, it
is 761 × 814 cells with 583 m² of free space (1163 m² before, half of it along those long
rays, where a global localizer would otherwise spread its particles). Every corrected pose
lies in a free cell of the cut map.

The map is built from the same scans the localizer then reads, so it explains them better
than a map made on another day would: results are an upper bound of what MCL achieves here.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.carmen import load_intel
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.stream import Dataset, Event, LaserScan
from slamkit.errors import ConfigError, InputError
from slamkit.mapping.occupancy import OccupancyMappingConfig, build_occupancy_map
from slamkit.maps import OCCUPIED_THRESHOLD, OccupancyGrid

__all__ = [
    "BuiltMapOptions",
    "build_localization_map",
    "crop_to_occupied",
    "load_intel_mcl",
    "localization_dataset",
]


@dataclass(frozen=True)
class BuiltMapOptions:
    """Options of :func:`load_intel_mcl` (metres, degrees where named)."""

    resolution: float = 0.05
    """Cell size of the built map [m]."""
    crop_margin: float = 1.0
    """The map is cut to the box of its occupied cells grown by this much [m]."""
    known_start: bool = False
    """False: no prior pose (global localization). True: the first corrected pose is the
    prior, with the CARMEN loader's small covariance (tracking)."""
    odometry_sigma_trans: float = 0.02
    """Noise added to each step's translation when deriving the odometry [m] (the CARMEN
    loader's default; drawn from ``default_rng(seed)``)."""
    odometry_sigma_rot_deg: float = 1.0
    """Noise added to each of a step's two rotations [deg] (the CARMEN loader's default)."""
    max_scans: int | None = None
    """Keep only the first this many scans for localization (all when ``None``); the map is
    always built from all of them."""

    def __post_init__(self) -> None:
        if not self.resolution > 0:
            raise ConfigError(f"resolution: expected a number > 0, got {self.resolution}")
        for name in ("crop_margin", "odometry_sigma_trans", "odometry_sigma_rot_deg"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"{name}: expected a number >= 0, got {getattr(self, name)}")
        if self.max_scans is not None and not self.max_scans >= 1:
            raise ConfigError(f"max_scans: expected an integer >= 1, got {self.max_scans}")


def crop_to_occupied(
    grid: OccupancyGrid, margin: float, occupied_threshold: float = OCCUPIED_THRESHOLD
) -> OccupancyGrid:
    """The part of ``grid`` covering its occupied cells (probability ``>= occupied_threshold``)
    grown by ``margin`` metres, on the same lattice (cells keep their values and positions).
    A grid without an occupied cell is returned unchanged."""
    if not isinstance(grid, OccupancyGrid):
        raise InputError(f"grid: expected an OccupancyGrid, got {type(grid).__name__}")
    if not margin >= 0:
        raise InputError(f"margin: expected a number >= 0, got {margin}")
    occupied = grid.occupied(occupied_threshold)
    rows = np.flatnonzero(occupied.any(axis=1))
    cols = np.flatnonzero(occupied.any(axis=0))
    if rows.size == 0:
        return grid
    m = int(np.ceil(margin / grid.resolution))
    r0, r1 = max(int(rows[0]) - m, 0), min(int(rows[-1]) + m + 1, grid.shape[0])
    c0, c1 = max(int(cols[0]) - m, 0), min(int(cols[-1]) + m + 1, grid.shape[1])
    origin = grid.origin_xy + grid.resolution * np.array([c0, r0], dtype=np.float64)
    return OccupancyGrid(grid.prob[r0:r1, c0:c1].copy(), grid.resolution, origin)


def build_localization_map(
    dataset: Dataset,
    resolution: float = 0.05,
    crop_margin: float = 1.0,
    config: OccupancyMappingConfig | None = None,
) -> tuple[OccupancyGrid, dict[str, Any]]:
    """The occupancy map of ``dataset`` built from its true poses, cut by
    :func:`crop_to_occupied`, and a JSON-able description (mapping configuration, cell
    counts, grid shapes before and after the cut, seconds)."""
    base = config if config is not None else OccupancyMappingConfig()
    cfg = dataclasses.replace(base, resolution=float(resolution), pose_source="truth")
    built = build_occupancy_map(dataset, cfg)
    grid = crop_to_occupied(built.grid, crop_margin)
    info: dict[str, Any] = {
        "mapping": config_to_dict(cfg),
        "crop_margin": float(crop_margin),
        "built_shape": list(built.grid.shape),
        "shape": list(grid.shape),
        "origin_xy": [float(v) for v in grid.origin_xy],
        "occupied_cells": int(np.count_nonzero(grid.occupied())),
        "free_cells": int(np.count_nonzero(grid.free())),
        "free_area_m2": float(np.count_nonzero(grid.free()) * grid.resolution**2),
        "mapping_seconds": float(built.stats.seconds),
        "scans_used": int(built.stats.scans_used),
    }
    return grid, info


def _first_scans(events: tuple[Event, ...], n: int) -> tuple[tuple[Event, ...], float]:
    """The events up to and including the ``n``-th scan, and that scan's time."""
    seen = 0
    for i, ev in enumerate(events):
        if isinstance(ev, LaserScan):
            seen += 1
            if seen == n:
                return events[: i + 1], ev.t
    return events, events[-1].t if events else 0.0


def localization_dataset(
    dataset: Dataset,
    grid: OccupancyGrid,
    *,
    known_start: bool = False,
    max_scans: int | None = None,
    name: str | None = None,
    description: str = "",
    map_info: Mapping[str, Any] | None = None,
) -> Dataset:
    """``dataset`` with ``grid`` as its ``known_grid``: without a prior pose unless
    ``known_start`` (then the data set's own prior stays), cut after the first ``max_scans``
    scans (the truth with it), renamed to ``name``; ``map_info`` goes into
    ``metadata["map"]``."""
    if not isinstance(grid, OccupancyGrid):
        raise InputError(f"grid: expected an OccupancyGrid, got {type(grid).__name__}")
    if dataset.laser is None:
        raise InputError(f"data set {dataset.name!r} has no laser: a grid map is of no use")
    events, truth = dataset.events, dataset.truth
    if max_scans is not None:
        events, t_end = _first_scans(events, int(max_scans))
        if truth.times is not None and truth.poses is not None:
            n = int(np.searchsorted(truth.times, t_end, side="right"))
            truth = dataclasses.replace(truth, times=truth.times[:n], poses=truth.poses[:n])
    metadata = {**dataset.metadata, "map": dict(map_info or {}), "known_start": known_start}
    if max_scans is not None:
        metadata["max_scans"] = int(max_scans)
    return dataclasses.replace(
        dataset,
        name=name or dataset.name,
        events=events,
        truth=truth,
        known_grid=grid,
        initial_pose=dataset.initial_pose if known_start else None,
        initial_cov=dataset.initial_cov if known_start else None,
        description=description or dataset.description,
        metadata=metadata,
    )


def load_intel_mcl(
    options: Mapping[str, Any] | None = None,
    *,
    seed: int = 0,
    data_root: Path | None = None,
) -> Dataset:
    """The Intel Research Lab log as a localization data set in the map slamkit builds from
    its corrected poses (module docstring): odometry = corrected motion + Gaussian noise of
    the given standard deviations drawn from ``default_rng(seed)``, scans, the built 5 cm map
    as ``known_grid``, the corrected path as truth, and no prior pose unless
    ``known_start``. ``options`` are the fields of :class:`BuiltMapOptions`."""
    opts = config_from_mapping(BuiltMapOptions, options, "intel-mcl")
    source = load_intel(
        {
            "odometry_sigma_trans": opts.odometry_sigma_trans,
            "odometry_sigma_rot_deg": opts.odometry_sigma_rot_deg,
        },
        seed=seed,
        data_root=data_root,
    )
    grid, info = build_localization_map(source, opts.resolution, opts.crop_margin)
    start = "known start" if opts.known_start else "no prior (global localization)"
    ds = localization_dataset(
        source,
        grid,
        known_start=opts.known_start,
        max_scans=opts.max_scans,
        name="intel-mcl",
        description=(
            f"Intel Research Lab in the {opts.resolution * 100:g} cm occupancy map built from "
            f"its corrected poses; odometry = corrected motion + known noise; {start}"
        ),
        map_info=info,
    )
    ds.metadata["carmen_config"] = source.provenance.options
    return ds.with_provenance(Provenance(options=config_to_dict(opts)))
