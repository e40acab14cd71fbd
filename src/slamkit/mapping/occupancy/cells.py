"""The per-cell path (``method="cell"``): every cell of a scan's window classified by the
inverse sensor model from its centre's range and bearing, optionally from a pre-computed
polar table of cell offsets around the sensor (``precompute=True``)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray
from slamkit.errors import ConfigError
from slamkit.geometry.angles import wrap_angle
from slamkit.mapping.bresenham import IntArray
from slamkit.mapping.grid import lattice_cells
from slamkit.mapping.inverse_model import (
    NO_INFORMATION,
    RegionArray,
    ResolvedModel,
    classify_cells,
    nearest_beam,
    ray_extents,
)
from slamkit.mapping.occupancy.scans import check_ranges

__all__ = ["PolarTable", "polar_table", "scan_cells_cell", "scan_cells_table"]

_MAX_TABLE_CELLS = 8_000_000  # largest pre-computed model (cells around the sensor)


def _unit(angles: FloatArray) -> tuple[FloatArray, FloatArray]:
    return np.cos(angles), np.sin(angles)


def _window_points(
    pose: FloatArray, beam_angles: FloatArray, d_end: FloatArray, beta: float
) -> FloatArray:
    """Sensor position and the ends of every beam and of its ±beta/2 edges ``(3B + 1, 2)``."""
    x, y, th = pose
    ang = th + np.concatenate([beam_angles - beta / 2, beam_angles, beam_angles + beta / 2])
    d = np.tile(d_end, 3)
    c, s = _unit(ang)
    return np.concatenate([[[x, y]], np.stack([x + d * c, y + d * s], axis=-1)])


def scan_cells_cell(
    pose: ArrayLike,
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    model: ResolvedModel,
    resolution: float,
) -> tuple[IntArray, RegionArray]:
    """Per-cell path: the lattice ``cells (N, 2)`` the scan says something about and their
    ``regions (N,)``, each cell once. Every cell of the window (the box around the sensor
    and the ends of all beams and beam edges, plus one cell) is classified by
    :func:`~slamkit.mapping.inverse_model.classify_cells` from its centre's range and
    bearing."""
    p = np.asarray(pose, dtype=np.float64)
    beams = np.asarray(beam_angles, dtype=np.float64)
    readings = check_ranges(ranges)
    _, d_end = ray_extents(readings, model)
    pts = _window_points(p, beams, d_end, min(model.beta, math.pi))
    lo = lattice_cells(pts.min(axis=0), resolution) - 1
    hi = lattice_cells(pts.max(axis=0), resolution) + 1
    rows = np.arange(lo[0], hi[0] + 1)
    cols = np.arange(lo[1], hi[1] + 1)
    dx = (cols + 0.5) * resolution - p[0]
    dy = (rows + 0.5) * resolution - p[1]
    r = np.hypot(dx[None, :], dy[:, None])
    phi = wrap_angle(np.arctan2(dy[:, None], dx[None, :]) - p[2])
    regions = classify_cells(r, phi, readings, beams, model)
    ir, ic = np.nonzero(regions)
    return np.stack([rows[ir], cols[ic]], axis=1), regions[ir, ic]


_TABLE_BINS = 4096  # bearing bins of the pre-computed model (0.088° each)


@dataclass(frozen=True, eq=False)
class PolarTable:
    """The pre-computed inverse-model geometry around a sensor sitting at a cell centre:
    every lattice offset ``(drow, dcol)`` within ``radius``, with the range ``r`` [m] and
    world bearing ``psi`` [rad] of that cell's centre. The offsets are grouped into
    ``n_bins`` equal bins of world bearing (``bin_start`` indexes each bin's first offset) and
    sorted by range within a bin, so a scan reads, bin by bin, only the offsets within reach
    of the beams that bin's bearings belong to. Independent of the heading (a scan's
    bearings are ``psi - theta``), so one table serves every scan."""

    resolution: float
    radius: float
    n_bins: int
    offsets: NDArray[np.int32]
    r: FloatArray
    psi: FloatArray
    bin_start: IntArray
    keys: FloatArray
    """``bin * key_scale + r``: increasing, so one ``searchsorted`` finds every bin's prefix."""
    key_scale: float

    def __len__(self) -> int:
        return int(self.r.size)

    @property
    def nbytes(self) -> int:
        arrays = (self.offsets, self.r, self.psi, self.bin_start, self.keys)
        return int(sum(a.nbytes for a in arrays))


@functools.lru_cache(maxsize=4)
def polar_table(resolution: float, radius: float, n_bins: int = _TABLE_BINS) -> PolarTable:
    """The :class:`PolarTable` for ``resolution`` and ``radius``, built once and cached."""
    n = math.ceil(radius / resolution) + 1
    if (2 * n + 1) ** 2 > _MAX_TABLE_CELLS * 4 / math.pi:
        raise ConfigError(
            f"pre-computed model: {radius:.1f} m at {resolution} m would hold "
            f"~{math.pi * n * n:.2e} cells; lower model.max_range or use precompute=false"
        )
    k = np.arange(-n, n + 1)
    drow, dcol = np.meshgrid(k, k, indexing="ij")
    r_all = np.hypot(drow, dcol) * resolution
    keep = r_all <= radius + resolution
    r = r_all[keep]
    psi = np.arctan2(drow[keep], dcol[keep]).astype(np.float64)
    width = 2.0 * math.pi / n_bins
    bins = np.minimum(((psi + math.pi) / width).astype(np.int64), n_bins - 1)
    order = np.lexsort((r, bins))
    scale = 2.0 * (radius + resolution) + 1.0
    offsets = np.stack([drow[keep], dcol[keep]], axis=1)[order].astype(np.int32)
    bin_start = np.searchsorted(bins[order], np.arange(n_bins + 1)).astype(np.int64)
    keys = bins[order] * scale + r[order]
    return PolarTable(
        resolution, radius, n_bins, offsets, r[order], psi[order], bin_start, keys, scale
    )


def scan_cells_table(
    table: PolarTable,
    pose: ArrayLike,
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    model: ResolvedModel,
) -> tuple[IntArray, RegionArray]:
    """Per-cell path with the pre-computed model: like :func:`scan_cells_cell` with the
    sensor snapped to the centre of its cell. For each bearing bin, the beams nearest to its
    two edges bound which beams its cells can belong to (a bin is narrower than half the beam
    spacing of any laser here); only the bin's offsets within the longer of those beams'
    reach are classified."""
    p = np.asarray(pose, dtype=np.float64)
    beams = np.asarray(beam_angles, dtype=np.float64)
    readings = check_ranges(ranges)
    _, d_end = ray_extents(readings, model)
    width = 2.0 * math.pi / table.n_bins
    edges = -math.pi + width * np.arange(table.n_bins + 1) - p[2]
    k_edge, d_edge = nearest_beam(wrap_angle(edges), beams)
    ok = d_edge <= 0.5 * model.beta + width
    reach = np.where(ok, d_end[k_edge], -1.0)
    limit = np.maximum(reach[:-1], reach[1:])  # per bin: its edges' beams
    stops = np.searchsorted(
        table.keys, np.arange(table.n_bins) * table.key_scale + limit, side="right"
    )
    starts = table.bin_start[:-1]
    counts = np.maximum(stops - starts, 0)
    first = np.cumsum(counts) - counts
    idx = np.repeat(starts - first, counts) + np.arange(int(counts.sum()))
    phi = wrap_angle(table.psi[idx] - p[2])
    regions = classify_cells(table.r[idx], phi, readings, beams, model)
    keep = regions != NO_INFORMATION
    centre = lattice_cells(p[:2], table.resolution)
    return table.offsets[idx[keep]].astype(np.int64) + centre, regions[keep]
