"""A growable grid of log odds on a lattice anchored at the world origin.

Every map slamkit builds at resolution ``res`` uses the same lattice: lattice cell ``(i, j)``
covers ``[j res, (j+1) res) × [i res, (i+1) res)`` (the cell convention of
:mod:`slamkit.maps.types`, rows along y). A :class:`LogOddsGrid` holds the block of lattice
rows ``row0 .. row0+rows-1`` and columns ``col0 .. col0+cols-1``; growing it only moves that
block, so cells computed for one scan stay valid, and two maps built at the same resolution
(say from the even and the odd scans of a log) line up cell for cell.

The grid applies one scan's cell regions as a single update per cell (:meth:`apply_scan`,
:meth:`apply_free_occupied`): where several readings of one scan touch the same cell,
"occupied" wins over "free" — a ray that grazes the wall cell where its neighbour's reading
ended must not erase that wall.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray, as_positive
from slamkit.errors import InputError
from slamkit.mapping.inverse_model import RegionArray, ResolvedModel
from slamkit.mapping.logodds import expit
from slamkit.maps import OccupancyGrid

__all__ = ["LogOddsGrid", "lattice_cells"]

IntArray = NDArray[np.int64]

DEFAULT_MAX_CELLS = 500_000_000
"""The largest grid a mapper allocates unless told otherwise: 2 GB of float32 log odds."""

_EXPIT_BLOCK = 1 << 16  # cells converted to probabilities at a time (512 kB of float64)


def lattice_cells(xy: FloatArray, resolution: float) -> IntArray:
    """Lattice cells ``(..., 2)`` ``(row, col)`` containing the points ``xy (..., 2)``."""
    p = np.asarray(xy, dtype=np.float64)
    return np.floor(p[..., ::-1] / resolution).astype(np.int64)


class LogOddsGrid:
    """Log odds ``(rows, cols)`` of lattice rows ``row0..`` and columns ``col0..`` (module
    docstring); every cell starts at the prior ``l0``. Mutable: it is the working state of a
    mapper; :meth:`to_occupancy_grid` returns an immutable probability grid."""

    def __init__(
        self,
        resolution: float,
        row0: int,
        col0: int,
        rows: int,
        cols: int,
        l0: float = 0.0,
        *,
        max_cells: int = DEFAULT_MAX_CELLS,
    ) -> None:
        self.resolution = as_positive(resolution, "resolution")
        self.max_cells = int(max_cells)
        if rows < 1 or cols < 1:
            raise InputError(f"grid size: expected at least 1 × 1 cells, got {rows} × {cols}")
        self.row0, self.col0 = int(row0), int(col0)
        self.l0 = float(l0)
        # float32: 4 bytes a cell; the clamped log odds (|l| < 10) keep 7 significant digits.
        self.log_odds: NDArray[np.float32] = self._prior_block(int(rows), int(cols))
        self._owner: NDArray[np.int32] | None = None  # scratch arrays of merge_scan
        self._kind: NDArray[np.int8] | None = None
        self._positions: NDArray[np.int32] = np.arange(0, dtype=np.int32)  # 0, 1, 2, ...

    @classmethod
    def covering(
        cls,
        xmin: float,
        ymin: float,
        xmax: float,
        ymax: float,
        resolution: float,
        l0: float,
        *,
        max_cells: int = DEFAULT_MAX_CELLS,
    ) -> LogOddsGrid:
        """The smallest block of lattice cells covering the box ``[xmin, xmax] × [ymin, ymax]``."""
        res = as_positive(resolution, "resolution")
        lo = lattice_cells(np.array([xmin, ymin]), res)
        hi = lattice_cells(np.array([xmax, ymax]), res)
        if np.any(hi < lo):
            raise InputError(f"grid bounds: empty box ({xmin}, {ymin}, {xmax}, {ymax})")
        rows, cols = int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)
        return cls(res, int(lo[0]), int(lo[1]), rows, cols, l0, max_cells=max_cells)

    def _prior_block(self, rows: int, cols: int) -> NDArray[np.float32]:
        if rows * cols > self.max_cells:
            raise InputError(
                f"a grid of {rows:,} × {cols:,} cells at {self.resolution:g} m "
                f"({4 * rows * cols / 1e9:.3g} GB) is above the limit of {self.max_cells:,} "
                "cells (max_cells): a coarser resolution or a shorter usable range, or raise it"
            )
        # A prior of 0.5 (l0 = 0) uses np.zeros, whose pages the OS hands out lazily: cells
        # no scan ever reaches then cost no memory traffic until they are read.
        if self.l0 == 0.0:
            return np.zeros((rows, cols), dtype=np.float32)
        return np.full((rows, cols), self.l0, dtype=np.float32)

    # -- geometry ----------------------------------------------------------------------------

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.log_odds.shape[0]), int(self.log_odds.shape[1]))

    @property
    def origin_xy(self) -> FloatArray:
        """World position of the lower-left corner of array cell ``(0, 0)``."""
        return np.array([self.col0 * self.resolution, self.row0 * self.resolution])

    @property
    def nbytes(self) -> int:
        """Bytes held: the log odds plus the scratch arrays of :meth:`apply_scan`."""
        extra = sum(a.nbytes for a in (self._owner, self._kind) if a is not None)
        return int(self.log_odds.nbytes + extra)

    def contains_cells(self, lo: IntArray, hi: IntArray) -> bool:
        """Whether lattice cells ``lo..hi`` (inclusive corners ``(row, col)``) are inside."""
        rows, cols = self.shape
        return bool(
            lo[0] >= self.row0
            and lo[1] >= self.col0
            and hi[0] < self.row0 + rows
            and hi[1] < self.col0 + cols
        )

    def grow_to_cells(self, lo: IntArray, hi: IntArray, margin_cells: int) -> bool:
        """Grow (never shrink) so lattice cells ``lo..hi`` fit, adding ``margin_cells`` on each
        side that has to grow (so a robot driving on does not reallocate every scan). Returns
        whether the grid grew. New cells hold the prior."""
        if self.contains_cells(lo, hi):
            return False
        rows, cols = self.shape
        m = max(int(margin_cells), 0)
        r0 = min(self.row0, int(lo[0]) - m) if lo[0] < self.row0 else self.row0
        c0 = min(self.col0, int(lo[1]) - m) if lo[1] < self.col0 else self.col0
        r_end = self.row0 + rows
        c_end = self.col0 + cols
        r1 = max(r_end, int(hi[0]) + 1 + m) if hi[0] >= r_end else r_end
        c1 = max(c_end, int(hi[1]) + 1 + m) if hi[1] >= c_end else c_end
        new = self._prior_block(r1 - r0, c1 - c0)
        new[self.row0 - r0 : self.row0 - r0 + rows, self.col0 - c0 : self.col0 - c0 + cols] = (
            self.log_odds
        )
        self.log_odds = new
        self.row0, self.col0 = r0, c0
        self._owner = self._kind = None
        return True

    def flat_index(self, cells: IntArray) -> tuple[IntArray, NDArray[np.bool_]]:
        """Flat array indices of lattice ``cells (N, 2)`` and which of them are inside."""
        rows, cols = self.shape
        r = cells[:, 0] - self.row0
        c = cells[:, 1] - self.col0
        inside = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
        return r * cols + c, inside

    # -- updates -----------------------------------------------------------------------------

    def _kind_scratch(self) -> NDArray[np.int8]:
        """Grid-sized int8 markers, all zero between scans (allocated on first use)."""
        if self._kind is None:
            self._kind = np.zeros(self.log_odds.size, dtype=np.int8)
        return self._kind

    def _owner_scratch(self) -> NDArray[np.int32]:
        """Grid-sized int32 slots for :meth:`merge_scan` (allocated on first use)."""
        if self._owner is None:
            self._owner = np.zeros(self.log_odds.size, dtype=np.int32)
        return self._owner

    def merge_scan(self, flat: IntArray, regions: RegionArray) -> tuple[IntArray, RegionArray]:
        """Each cell once: the distinct flat indices among the cells a scan touched and their
        merged region, occupied winning over free (cells with region 0 dropped). O(n) with
        two grid-sized scratch arrays instead of a sort: the largest region of each cell is
        gathered with ``np.maximum.at``; then every position writes its index into the cell's
        slot of ``owner``, and the one position whose index survived represents the cell."""
        owner, kind = self._owner_scratch(), self._kind_scratch()
        np.maximum.at(kind, flat, regions)
        pos = np.arange(flat.size, dtype=np.int32)
        owner[flat] = pos  # with repeated cells one of the positions is stored …
        unique = flat[owner[flat] == pos]  # … and exactly that one is kept
        merged = kind[unique]
        kind[unique] = 0
        informative = merged != 0
        return unique[informative], merged[informative]

    def apply(
        self, flat: IntArray, delta: FloatArray, model: ResolvedModel, min_change: float = 0.0
    ) -> int:
        """Add ``delta`` to the log odds of the distinct cells ``flat`` and clamp:
        ``l <- clamp(l + delta)`` (the log-odds Bayes update with the increments of the
        inverse model). With ``min_change > 0`` a cell is left alone when the update would
        move its probability by less than ``min_change`` (selective updating: e.g. a cell
        already clamped at "free" seen free again). Returns the number of cells changed."""
        lo = self.log_odds.reshape(-1)
        old = lo[flat]
        new = np.clip(old + delta, model.l_min, model.l_max)
        if min_change > 0.0:
            keep = np.abs(expit(new) - expit(old)) >= min_change
            flat, new = flat[keep], new[keep]
        lo[flat] = new
        return int(flat.size)

    def apply_scan(
        self,
        flat: IntArray,
        regions: RegionArray,
        model: ResolvedModel,
        min_change: float = 0.0,
        box: tuple[int, int, int, int] | None = None,
    ) -> int:
        """One update per cell for a scan's (possibly repeated) cells, occupied winning over
        free; returns the number of distinct cells updated.

        With ``box = (row_lo, col_lo, row_hi, col_hi)``, array cells (inclusive) holding every
        cell in ``flat``, and no selective updating, the repeated cells are not removed at
        all: every copy of a cell reads the same old value and writes the same new one, and
        the distinct cells are counted in the box. Otherwise :meth:`merge_scan`, then
        :meth:`apply` on the distinct cells.
        """
        if box is None or min_change > 0.0:
            unique, merged = self.merge_scan(flat, regions)
            return self.apply(unique, model.delta(merged), model, min_change)
        kind = self._kind_scratch()
        np.maximum.at(kind, flat, regions)
        r0, c0, r1, c1 = box
        n = int(np.count_nonzero(kind.reshape(self.shape)[r0 : r1 + 1, c0 : c1 + 1]))
        increments = np.array([0.0, model.delta_free, model.delta_occ], dtype=np.float32)
        values = self.log_odds.reshape(-1)
        new = values[flat] + increments[kind[flat]]
        np.clip(new, model.l_min, model.l_max, out=new)
        values[flat] = new  # repeated cells write identical values
        kind[flat] = 0
        return n

    def _flat_values(self) -> NDArray[np.float32]:
        """The log odds as a flat view (made C-contiguous first if someone replaced them)."""
        if not self.log_odds.flags.c_contiguous:
            self.log_odds = np.ascontiguousarray(self.log_odds)
        return self.log_odds.reshape(-1)

    def _arange(self, n: int) -> NDArray[np.int32]:
        """``0 .. n-1`` as int32, a slice of a buffer kept between calls."""
        if self._positions.size < n:
            self._positions = np.arange(max(n, 2 * self._positions.size), dtype=np.int32)
        return self._positions[:n]

    def apply_free_occupied(self, flat: IntArray, n_free: int, model: ResolvedModel) -> int:
        """One update per cell for one scan whose cells ``flat[:n_free]`` are free and
        ``flat[n_free:]`` occupied (flat indices into this grid, repeats allowed, not checked:
        a negative index would wrap): a cell in both gets the occupied increment only.
        Returns the number of distinct cells updated.

        The log-odds Bayes update ``l <- clamp(l + delta)`` in float32, without removing the
        repeated cells: every copy of a cell reads the same old value and computes the same
        new one, and the occupied cells are written after the free ones. The distinct cells
        are counted with the grid itself as scratch: after the old values are read, each
        position ``p`` writes the int32 ``p`` into its cell's 4 bytes (a view of the float32
        log odds); one position per distinct cell finds its own number there afterwards. The
        new values then overwrite every tagged cell. No grid-sized scratch array is needed.
        """
        values = self._flat_values()
        new = values.take(flat)  # the old log odds, before any cell is written
        positions = self._arange(flat.size)
        tags = values.view(np.int32)
        tags[flat] = positions
        n = int(np.count_nonzero(tags.take(flat) == positions))
        new[:n_free] += np.float32(model.delta_free)
        new[n_free:] += np.float32(model.delta_occ)
        np.clip(new, np.float32(model.l_min), np.float32(model.l_max), out=new)
        values[flat[:n_free]] = new[:n_free]
        values[flat[n_free:]] = new[n_free:]  # after the free cells: occupied wins
        return n

    def apply_readings(
        self, flat: IntArray, regions: RegionArray, model: ResolvedModel, min_change: float = 0.0
    ) -> int:
        """One update per reading: every (cell, reading) pair adds its increment (a cell
        crossed by five rays of a scan gets five free updates), then the sum is clamped."""
        touched = regions != 0
        flat, regions = flat[touched], regions[touched]
        unique, inverse = np.unique(flat, return_inverse=True)
        delta = np.bincount(inverse, weights=model.delta(regions), minlength=unique.size)
        return self.apply(unique, delta.astype(np.float64), model, min_change)

    # -- output ------------------------------------------------------------------------------

    def probabilities(self) -> FloatArray:
        """``expit(log odds)`` of every cell, a new array.

        Converted in blocks of :data:`_EXPIT_BLOCK` cells, so that :func:`expit`'s float64
        temporaries stay small and in cache: on a large grid, writing fresh grid-sized
        temporaries (page faults on first touch) costs more than the arithmetic. The same
        numbers as ``expit(self.log_odds)``, an element-wise function."""
        src = self.log_odds.reshape(-1)
        out = np.empty(src.size, dtype=np.float64)
        for k in range(0, src.size, _EXPIT_BLOCK):
            out[k : k + _EXPIT_BLOCK] = expit(src[k : k + _EXPIT_BLOCK])
        return out.reshape(self.log_odds.shape)

    def to_occupancy_grid(self) -> OccupancyGrid:
        """The map as an :class:`OccupancyGrid` of probabilities (a copy)."""
        return OccupancyGrid(self.probabilities(), self.resolution, self.origin_xy)

    def copy(self) -> LogOddsGrid:
        out = LogOddsGrid(
            self.resolution, self.row0, self.col0, *self.shape, l0=self.l0,
            max_cells=self.max_cells,
        )  # fmt: skip
        out.log_odds = self.log_odds.copy()
        return out
