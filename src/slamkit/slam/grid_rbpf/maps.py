"""Per-particle occupancy grids that share their tiles (copy-on-write).

A Rao-Blackwellized particle filter gives every particle its own map, and resampling
duplicates particles: copying whole grids there would cost ``P × cells`` per resampling and
as much memory. Here the lattice of :mod:`slamkit.mapping.grid` (cell ``(i, j)`` covers
``[j res, (j+1) res) × [i res, (i+1) res)``) is cut into square tiles of ``tile_cells``
cells a side; tile ``(a, b)`` holds lattice rows ``a T .. a T + T - 1`` and columns
``b T ..``. A :class:`TiledMap` maps tile coordinates to tiles of a :class:`TilePool`, which
counts how many maps refer to each tile. :meth:`TiledMap.share` (what resampling does) only
copies the small dictionary and raises the counts; a map that writes a tile it shares first
copies it (copy-on-write) and lowers the count of the original; a tile no map refers to is
freed. A tile never written is not stored at all: it reads as the prior ``l0``.

The scan update is the log-odds Bayes update of :class:`~slamkit.mapping.grid.LogOddsGrid`
(``l ← clamp(l + δ)`` in float32, one update per cell and scan, occupied winning over free),
applied to the lattice cells :func:`scan_cells` traces (Bresenham rays of
:mod:`slamkit.mapping.occupancy.rays`), so a shared map reads bit for bit as an
independently copied dense grid updated with the same scans.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.errors import InputError
from slamkit.mapping.bresenham import IntArray
from slamkit.mapping.grid import LogOddsGrid
from slamkit.mapping.inverse_model import FREE, OCCUPIED, RegionArray, ResolvedModel
from slamkit.mapping.occupancy.rays import scan_rays, trace_rays

__all__ = ["TilePool", "TiledMap", "scan_cells"]

Tile = NDArray[np.float32]


def scan_cells(
    sensor_pose: FloatArray,
    ranges: FloatArray,
    beam_angles: FloatArray,
    model: ResolvedModel,
    resolution: float,
) -> tuple[IntArray, IntArray, RegionArray]:
    """Lattice ``rows (N,)``, ``cols (N,)`` and regions (:data:`FREE`, :data:`OCCUPIED`) of
    the cells one scan ``ranges (B,)`` from ``sensor_pose (3,)`` informs: every traced cell
    of every ray, repeats included, cells without information dropped."""
    rays = scan_rays(sensor_pose, ranges, beam_angles, model, resolution)
    rows, cols, regions, _ = trace_rays(rays, resolution, 0, 0)
    keep = regions != 0
    return rows[keep], cols[keep], regions[keep]


class TilePool:
    """The tiles of all particles' maps with their reference counts (module docstring).
    ``tile_cells``: cells per tile side (a power of two); ``l0``: the prior log odds."""

    def __init__(self, resolution: float, tile_cells: int = 64, l0: float = 0.0) -> None:
        if tile_cells < 1 or tile_cells & (tile_cells - 1):
            raise InputError(f"tile_cells: expected a power of two, got {tile_cells!r}")
        self.resolution = float(resolution)
        self.tile_cells = int(tile_cells)
        self.shift = int(tile_cells).bit_length() - 1
        self.l0 = np.float32(l0)
        self._data: dict[int, Tile] = {}
        self._refs: dict[int, int] = {}
        self._next = 0
        self.copies = 0
        """Tiles copied because a map wrote a shared one (copy-on-write)."""
        self.peak_tiles = 0

    def new_map(self) -> TiledMap:
        """An empty map (every cell at the prior)."""
        return TiledMap(self, {})

    @property
    def tiles_alive(self) -> int:
        return len(self._data)

    @property
    def nbytes(self) -> int:
        """Bytes of tile data held."""
        return len(self._data) * self.tile_cells * self.tile_cells * 4

    def refcount(self, tile_id: int) -> int:
        return self._refs.get(tile_id, 0)

    def tile(self, tile_id: int) -> Tile:
        """The tile's log odds ``(T, T)`` (read them; write only through a map)."""
        return self._data[tile_id]

    def add(self, data: Tile) -> int:
        """Store ``data`` as a new tile with one reference; its id."""
        tid = self._next
        self._next += 1
        self._data[tid] = data
        self._refs[tid] = 1
        self.peak_tiles = max(self.peak_tiles, len(self._data))
        return tid

    def acquire(self, tile_id: int) -> None:
        self._refs[tile_id] += 1

    def release(self, tile_id: int) -> None:
        n = self._refs[tile_id] - 1
        if n:
            self._refs[tile_id] = n
        else:
            del self._refs[tile_id], self._data[tile_id]

    def stats(self) -> dict[str, int]:
        """Tiles alive, their bytes, the peak count and the copy-on-write copies so far."""
        return {
            "tile_cells": self.tile_cells,
            "tiles_alive": self.tiles_alive,
            "tile_bytes": self.nbytes,
            "peak_tiles": self.peak_tiles,
            "peak_bytes": self.peak_tiles * self.tile_cells * self.tile_cells * 4,
            "cow_copies": self.copies,
        }


class TiledMap:
    """One particle's map: tile coordinates ``(a, b)`` → tile ids of its :class:`TilePool`
    (module docstring). Made by :meth:`TilePool.new_map` or :meth:`share`."""

    def __init__(self, pool: TilePool, tiles: dict[tuple[int, int], int]) -> None:
        self.pool = pool
        self.tiles = tiles

    def share(self) -> TiledMap:
        """A second map with the same cells that shares every tile (no cell is copied)."""
        for tid in self.tiles.values():
            self.pool.acquire(tid)
        return TiledMap(self.pool, dict(self.tiles))

    def release(self) -> None:
        """Drop this map's references (the map is empty afterwards)."""
        for tid in self.tiles.values():
            self.pool.release(tid)
        self.tiles = {}

    def _store(self, key: tuple[int, int], data: Tile) -> None:
        """Make ``data`` the cells of tile ``key``: written in place when this map alone
        refers to the tile, else into a new tile of its own (copy-on-write; the shared
        original loses one reference)."""
        pool = self.pool
        tid = self.tiles.get(key)
        if tid is not None and pool.refcount(tid) == 1:
            pool.tile(tid)[:, :] = data
            return
        if tid is not None:
            pool.copies += 1
            pool.release(tid)
        self.tiles[key] = pool.add(data.copy())

    def window(self, row0: int, col0: int, rows: int, cols: int) -> Tile:
        """The log odds of lattice rows ``row0 .. row0+rows-1`` and columns ``col0 ..``, a
        new ``(rows, cols)`` float32 array (cells of unstored tiles read ``l0``)."""
        pool = self.pool
        s, t = pool.shift, pool.tile_cells
        out = np.full((rows, cols), pool.l0, dtype=np.float32)
        r1, c1 = row0 + rows, col0 + cols
        for a in range(row0 >> s, ((r1 - 1) >> s) + 1):
            for b in range(col0 >> s, ((c1 - 1) >> s) + 1):
                tid = self.tiles.get((a, b))
                if tid is None:
                    continue
                # the overlap of tile (a, b) with the window, in lattice cells
                ra, rb = max(row0, a * t), min(r1, (a + 1) * t)
                ca, cb = max(col0, b * t), min(c1, (b + 1) * t)
                out[ra - row0 : rb - row0, ca - col0 : cb - col0] = pool.tile(tid)[
                    ra - a * t : rb - a * t, ca - b * t : cb - b * t
                ]
        return out

    def integrate(
        self, rows: IntArray, cols: IntArray, regions: RegionArray, model: ResolvedModel
    ) -> int:
        """One scan's lattice cells (:func:`scan_cells`): ``l ← clamp(l + δ)`` once per
        distinct cell, occupied winning over free; returns the number of cells written
        (repeats included). Only the tiles the scan touches are written (and copied if
        shared)."""
        if rows.size == 0:
            return 0
        pool = self.pool
        s, t = pool.shift, pool.tile_cells
        # The window: the whole tiles the cells fall in.
        ta0, tb0 = int(rows.min()) >> s, int(cols.min()) >> s
        ta1, tb1 = int(rows.max()) >> s, int(cols.max()) >> s
        row0, col0 = ta0 * t, tb0 * t
        n_rows, n_cols = (ta1 - ta0 + 1) * t, (tb1 - tb0 + 1) * t
        win = self.window(row0, col0, n_rows, n_cols)
        values = win.reshape(-1)
        flat = (rows - row0) * n_cols + (cols - col0)
        free = regions == FREE
        occ = regions == OCCUPIED
        # Every copy of a cell reads the old value; the occupied cells are written after the
        # free ones, so a cell in both regions gets the occupied increment only.
        new = values.take(flat)
        new[free] += np.float32(model.delta_free)
        new[occ] += np.float32(model.delta_occ)
        np.clip(new, np.float32(model.l_min), np.float32(model.l_max), out=new)
        values[flat[free]] = new[free]
        values[flat[occ]] = new[occ]
        # The tiles touched: a count per tile of the window.
        tiles_b = tb1 - tb0 + 1
        local = ((rows >> s) - ta0) * tiles_b + ((cols >> s) - tb0)
        touched = np.flatnonzero(np.bincount(local, minlength=(ta1 - ta0 + 1) * tiles_b))
        for k in touched.tolist():
            a, b = divmod(k, tiles_b)
            self._store((ta0 + a, tb0 + b), win[a * t : (a + 1) * t, b * t : (b + 1) * t])
        return int(flat.size)

    def bounds_cells(self) -> tuple[int, int, int, int] | None:
        """``(row0, col0, rows, cols)`` of the lattice block covering the stored tiles."""
        if not self.tiles:
            return None
        keys = np.array(list(self.tiles), dtype=np.int64)
        t = self.pool.tile_cells
        lo, hi = keys.min(axis=0), keys.max(axis=0)
        return (
            int(lo[0]) * t,
            int(lo[1]) * t,
            int(hi[0] - lo[0] + 1) * t,
            int(hi[1] - lo[1] + 1) * t,
        )

    def to_log_odds_grid(self) -> LogOddsGrid | None:
        """The map as one dense :class:`LogOddsGrid` over its stored tiles (a copy; None
        while empty)."""
        box = self.bounds_cells()
        if box is None:
            return None
        row0, col0, rows, cols = box
        grid = LogOddsGrid(self.pool.resolution, row0, col0, rows, cols, float(self.pool.l0))
        grid.log_odds = self.window(row0, col0, rows, cols)
        return grid

    def log_odds_at(self, rows: IntArray, cols: IntArray) -> FloatArray:
        """The log odds of lattice cells ``(rows, cols)`` (for tests and diagnosis)."""
        pool = self.pool
        s, t = pool.shift, pool.tile_cells
        out = np.full(rows.shape, float(pool.l0))
        for k in range(rows.size):
            tid = self.tiles.get((int(rows[k]) >> s, int(cols[k]) >> s))
            if tid is not None:
                out[k] = pool.tile(tid)[int(rows[k]) & (t - 1), int(cols[k]) & (t - 1)]
        return out
