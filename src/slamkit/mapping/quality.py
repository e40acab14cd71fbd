"""How good is an occupancy map? Numbers that need no ground truth, and two that do.

* :func:`map_quality` — the fractions of occupied, free and unknown cells (thresholds on the
  probability) and the map's entropy ``H = sum_i h(p_i)`` in bits, with
  ``h(p) = -p log2 p - (1-p) log2(1-p)`` (1 bit for an unknown cell, 0 for a certain one).
* :func:`map_agreement` — how two maps of the same place agree: over the cells *both*
  classify as known (occupied or free), the fraction they classify the same.
  :func:`even_odd_agreement` builds one map from the even and one from the odd scans of a log
  (on the same grid, :func:`even_odd_maps`) and compares them: a self-consistency check of
  poses and model, since the two halves share no scan.
* :func:`occupied_precision_recall` — against a true occupancy grid: the fraction of mapped
  occupied cells that lie on (or within ``tolerance_cells`` of) a true occupied cell, and
  the fraction of true occupied cells with a mapped occupied cell that close.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from slamkit.datasets.stream import Dataset
from slamkit.errors import InputError
from slamkit.mapping.occupancy import (
    OccupancyMappingConfig,
    OccupancyMapResult,
    build_occupancy_map,
    data_bounds,
)
from slamkit.maps import FREE_THRESHOLD, OCCUPIED_THRESHOLD, OccupancyGrid

__all__ = [
    "FREE_THRESHOLD",
    "OCCUPIED_THRESHOLD",
    "MapQuality",
    "check_thresholds",
    "classify_grid",
    "even_odd_agreement",
    "even_odd_maps",
    "map_agreement",
    "map_entropy",
    "map_quality",
    "occupied_precision_recall",
]

# OCCUPIED_THRESHOLD / FREE_THRESHOLD (defined in slamkit.maps.types, re-exported here) are
# the one classification of built maps: the quality report, the map agreement,
# precision/recall and the ROS export (slamkit.io.rosmap writes these numbers into map.yaml).
# With the default inverse model (p_occ 0.75, p_free 0.45) one occupied reading makes a prior
# cell occupied, while it takes four free readings (net) to make it free (0.45, 0.40, 0.354,
# 0.309).


def check_thresholds(occupied_threshold: float, free_threshold: float) -> None:
    """Raise :class:`InputError` unless ``0 <= free < occupied <= 1``."""
    if not 0.0 <= free_threshold < occupied_threshold <= 1.0:
        raise InputError(
            f"thresholds: expected 0 <= free < occupied <= 1, got free {free_threshold}, "
            f"occupied {occupied_threshold}"
        )


def classify_grid(
    grid: OccupancyGrid,
    occupied_threshold: float = OCCUPIED_THRESHOLD,
    free_threshold: float = FREE_THRESHOLD,
) -> NDArray[np.int8]:
    """Cell classes: 2 occupied (``p >= occupied_threshold``), 1 free
    (``p <= free_threshold``), 0 unknown."""
    check_thresholds(occupied_threshold, free_threshold)
    out = np.zeros(grid.shape, dtype=np.int8)
    out[grid.prob <= free_threshold] = 1
    out[grid.prob >= occupied_threshold] = 2
    return out


def map_entropy(grid: OccupancyGrid) -> float:
    """Sum of the cells' binary entropies [bits]."""
    p = np.clip(grid.prob, 1e-300, 1.0)
    q = np.clip(1.0 - grid.prob, 1e-300, 1.0)
    h = -(grid.prob * np.log2(p) + (1.0 - grid.prob) * np.log2(q))
    return float(h.sum())


@dataclass(frozen=True)
class MapQuality:
    """Ground-truth-free numbers of a map (module docstring); fractions of all cells."""

    cells: int
    occupied_fraction: float
    free_fraction: float
    unknown_fraction: float
    entropy_bits: float
    entropy_bits_per_cell: float
    area_known_m2: float
    occupied_threshold: float
    free_threshold: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def map_quality(
    grid: OccupancyGrid,
    occupied_threshold: float = OCCUPIED_THRESHOLD,
    free_threshold: float = FREE_THRESHOLD,
) -> MapQuality:
    """Occupied/free/unknown fractions and entropy of ``grid``."""
    cls = classify_grid(grid, occupied_threshold, free_threshold)
    n = cls.size
    occ = int(np.count_nonzero(cls == 2))
    free = int(np.count_nonzero(cls == 1))
    h = map_entropy(grid)
    return MapQuality(
        cells=n,
        occupied_fraction=occ / n,
        free_fraction=free / n,
        unknown_fraction=(n - occ - free) / n,
        entropy_bits=h,
        entropy_bits_per_cell=h / n,
        area_known_m2=(occ + free) * grid.resolution**2,
        occupied_threshold=occupied_threshold,
        free_threshold=free_threshold,
    )


def _overlap(a: OccupancyGrid, b: OccupancyGrid) -> tuple[tuple[slice, slice], tuple[slice, slice]]:
    """Index windows of the common cells of two grids on the same lattice."""
    if not math.isclose(a.resolution, b.resolution, rel_tol=1e-9):
        raise InputError(
            f"map agreement: expected equal resolutions, got {a.resolution} and {b.resolution}"
        )
    shift = (b.origin_xy - a.origin_xy) / a.resolution  # b's cell (0, 0) in a's cells (x, y)
    cells = np.round(shift)
    if np.any(np.abs(shift - cells) > 1e-6):
        raise InputError("map agreement: the grids' cells do not line up (origin offset)")
    dc, dr = int(cells[0]), int(cells[1])
    r0, r1 = max(0, dr), min(a.shape[0], dr + b.shape[0])
    c0, c1 = max(0, dc), min(a.shape[1], dc + b.shape[1])
    if r1 <= r0 or c1 <= c0:
        raise InputError("map agreement: the grids do not overlap")
    return (slice(r0, r1), slice(c0, c1)), (slice(r0 - dr, r1 - dr), slice(c0 - dc, c1 - dc))


def map_agreement(
    a: OccupancyGrid,
    b: OccupancyGrid,
    occupied_threshold: float = OCCUPIED_THRESHOLD,
    free_threshold: float = FREE_THRESHOLD,
) -> dict[str, Any]:
    """Cell-wise agreement of two maps on the same lattice (module docstring).

    Returns ``agreement`` (equal classes among cells both call known), ``both_known`` (their
    number), ``occupied_agreement`` (cells both call occupied over cells either calls
    occupied, among the cells both call known) and the confusion counts.
    """
    wa, wb = _overlap(a, b)
    ca = classify_grid(a, occupied_threshold, free_threshold)[wa]
    cb = classify_grid(b, occupied_threshold, free_threshold)[wb]
    known = (ca > 0) & (cb > 0)
    n = int(np.count_nonzero(known))
    same = int(np.count_nonzero(known & (ca == cb)))
    occ_both = int(np.count_nonzero(known & (ca == 2) & (cb == 2)))
    occ_either = int(np.count_nonzero(known & ((ca == 2) | (cb == 2))))
    return {
        "agreement": same / n if n else None,
        "both_known": n,
        "occupied_agreement": occ_both / occ_either if occ_either else None,
        "free_free": int(np.count_nonzero(known & (ca == 1) & (cb == 1))),
        "occupied_occupied": occ_both,
        "free_occupied": int(np.count_nonzero(known & (ca == 1) & (cb == 2))),
        "occupied_free": int(np.count_nonzero(known & (ca == 2) & (cb == 1))),
    }


def even_odd_maps(
    dataset: Dataset,
    config: OccupancyMappingConfig | None = None,
    *,
    bounds: tuple[float, float, float, float] | None = None,
) -> tuple[OccupancyMapResult, OccupancyMapResult]:
    """The maps of the even and of the odd scans of ``dataset`` (index in the data set's
    scans; ``config.scan_stride`` then applies within each half) on one grid: ``bounds``,
    default the bounds of all scans (:func:`data_bounds`).

    Together they cost about what the map of all scans costs: the two halves trace the same
    rays between them, each on a grid of the full size (pass the full map's
    :attr:`OccupancyMapResult.bounds` to skip recomputing the bounds). The even map is the
    map with ``scan_stride=2``."""
    cfg = config if config is not None else OccupancyMappingConfig()
    if bounds is None:
        bounds = data_bounds(dataset, cfg)
    even = build_occupancy_map(dataset, cfg, scans=slice(0, None, 2), bounds=bounds)
    odd = build_occupancy_map(dataset, cfg, scans=slice(1, None, 2), bounds=bounds)
    return even, odd


def even_odd_agreement(
    dataset: Dataset,
    config: OccupancyMappingConfig | None = None,
    *,
    bounds: tuple[float, float, float, float] | None = None,
) -> dict[str, Any]:
    """:func:`map_agreement` of the :func:`even_odd_maps` of ``dataset``, plus how many scans
    each used."""
    even, odd = even_odd_maps(dataset, config, bounds=bounds)
    out = map_agreement(even.grid, odd.grid)
    out["scans_even"] = even.stats.scans_used
    out["scans_odd"] = odd.stats.scans_used
    return out


def _project(
    src: OccupancyGrid, mask: NDArray[np.bool_], dst: OccupancyGrid
) -> tuple[NDArray[np.bool_], int]:
    """Cells of ``dst`` that hold the centre of at least one ``mask`` cell of ``src``, and how
    many ``mask`` cells have their centre outside ``dst``."""
    idx = np.argwhere(mask)
    cells = dst.world_to_cell(src.cell_to_world(idx))
    inside = dst.contains(cells)
    out = np.zeros(dst.shape, dtype=bool)
    out[cells[inside, 0], cells[inside, 1]] = True
    return out, int(np.count_nonzero(~inside))


def occupied_precision_recall(
    grid: OccupancyGrid,
    truth: OccupancyGrid,
    *,
    tolerance_cells: int = 1,
    occupied_threshold: float = OCCUPIED_THRESHOLD,
    free_threshold: float = FREE_THRESHOLD,
    truth_threshold: float = 0.5,
) -> dict[str, Any]:
    """Precision and recall of ``grid``'s occupied cells against ``truth`` (module
    docstring). Both are compared on the coarser of the two lattices: a coarse cell is
    (truly / mapped) occupied if it holds the centre of a finer such cell. A match may lie up
    to ``tolerance_cells`` away (Chebyshev distance, in cells of that lattice). True occupied
    cells outside the map count as missed. ``recall_observed`` counts only the true occupied
    cells the map knows something about (a known map cell within the tolerance): walls the
    sensor never saw cannot be recalled by any mapper."""
    if tolerance_cells < 0:
        raise InputError(f"tolerance_cells: expected >= 0, got {tolerance_cells}")
    cls = classify_grid(grid, occupied_threshold, free_threshold)
    true_mask = truth.prob >= truth_threshold
    if grid.resolution >= truth.resolution * (1 - 1e-9):  # compare on the map's cells
        mapped = cls == 2
        known = cls > 0
        true_occ, missed_outside = _project(truth, true_mask, grid)
        lattice = grid
    else:  # the map is finer: compare on the truth's cells
        mapped, _ = _project(grid, cls == 2, truth)
        known, _ = _project(grid, cls > 0, truth)
        true_occ, missed_outside = true_mask, 0
        lattice = truth
    size = 2 * tolerance_cells + 1
    structure = np.ones((size, size), dtype=bool)
    near_true = ndimage.binary_dilation(true_occ, structure)
    near_mapped = ndimage.binary_dilation(mapped, structure)
    near_known = ndimage.binary_dilation(known, structure)
    n_mapped = int(np.count_nonzero(mapped))
    n_true = int(np.count_nonzero(true_occ)) + missed_outside
    observed = true_occ & near_known
    n_obs = int(np.count_nonzero(observed))
    return {
        "precision": int(np.count_nonzero(mapped & near_true)) / n_mapped if n_mapped else None,
        "recall": int(np.count_nonzero(true_occ & near_mapped)) / n_true if n_true else None,
        "recall_observed": (
            int(np.count_nonzero(observed & near_mapped)) / n_obs if n_obs else None
        ),
        "mapped_occupied": n_mapped,
        "true_occupied": n_true,
        "true_occupied_observed": n_obs,
        "tolerance_cells": tolerance_cells,
        "lattice_resolution": lattice.resolution,
    }
