"""Map representations shared by the simulator, the sensor models and the estimators.

* :class:`LandmarkMap` – point landmarks with integer identities.
* :class:`SegmentMap` – wall segments (the simulator's laser worlds).
* :class:`OccupancyGrid` – a regular grid of occupancy probabilities.

Grid convention (the one place it is defined): cell ``(row, col)`` covers the world square
``[origin_x + col*res, origin_x + (col+1)*res) × [origin_y + row*res, origin_y + (row+1)*res)``,
i.e. rows grow with y and columns with x; ``origin_xy`` is the world position of the lower-left
corner of cell ``(0, 0)``. Probabilities: 0 free, 1 occupied, :data:`UNKNOWN` (0.5) unknown.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_positive
from slamkit.errors import InputError, ShapeError

__all__ = [
    "FREE_THRESHOLD",
    "OCCUPIED_THRESHOLD",
    "UNKNOWN",
    "LandmarkMap",
    "OccupancyGrid",
    "SegmentMap",
]

UNKNOWN = 0.5
OCCUPIED_THRESHOLD = 0.65
"""An occupancy-grid cell with probability at least this is occupied — the one
classification of grids in slamkit: :meth:`OccupancyGrid.occupied`, the likelihood field,
ray casting, the quality report of built maps (:mod:`slamkit.mapping.quality`, where the
choice is discussed) and the ROS export all use it."""
FREE_THRESHOLD = 0.35
"""An occupancy-grid cell with probability at most this is free (see
:data:`OCCUPIED_THRESHOLD`)."""


@dataclass(frozen=True)
class LandmarkMap:
    """Point landmarks: ``positions (M, 2)`` in metres and unique integer ``ids (M,)``."""

    positions: FloatArray
    ids: NDArray[np.int64]

    def __post_init__(self) -> None:
        pos = as_array(self.positions, "landmark positions", (None, 2))
        ids = np.asarray(self.ids)
        if ids.shape != (pos.shape[0],) or not np.issubdtype(ids.dtype, np.integer):
            raise ShapeError(
                f"landmark ids: expected {pos.shape[0]} integers, got shape {ids.shape} "
                f"of {ids.dtype}"
            )
        if np.unique(ids).size != ids.size:
            raise InputError("landmark ids: expected unique ids, got duplicates")
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "ids", ids.astype(np.int64))

    @classmethod
    def from_positions(cls, positions: ArrayLike) -> LandmarkMap:
        """Landmarks numbered ``0 .. M-1`` in the given order."""
        pos = as_array(positions, "landmark positions", (None, 2))
        return cls(pos, np.arange(pos.shape[0], dtype=np.int64))

    def __len__(self) -> int:
        return int(self.ids.size)

    def position_of(self, ids: ArrayLike) -> FloatArray:
        """Positions ``(K, 2)`` of the landmarks with the given ids (KeyError-free lookup)."""
        want = np.asarray(ids, dtype=np.int64)
        order = np.argsort(self.ids)
        idx = np.searchsorted(self.ids, want, sorter=order)
        idx = np.clip(idx, 0, self.ids.size - 1)
        found = order[idx]
        if np.any(self.ids[found] != want):
            missing = sorted(set(want.tolist()) - set(self.ids.tolist()))
            raise InputError(f"landmark ids not in the map: {missing[:10]}")
        return self.positions[found]


@dataclass(frozen=True)
class SegmentMap:
    """Wall segments ``(S, 2, 2)``: segment ``s`` runs from ``segments[s, 0]`` to
    ``segments[s, 1]`` (metres)."""

    segments: FloatArray

    def __post_init__(self) -> None:
        seg = as_array(self.segments, "segments", (None, 2, 2))
        object.__setattr__(self, "segments", seg)

    def __len__(self) -> int:
        return int(self.segments.shape[0])

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of all segment end points."""
        pts = self.segments.reshape(-1, 2)
        return (
            float(pts[:, 0].min()),
            float(pts[:, 1].min()),
            float(pts[:, 0].max()),
            float(pts[:, 1].max()),
        )


@dataclass(frozen=True)
class OccupancyGrid:
    """Occupancy probabilities ``prob (rows, cols)`` on a grid of ``resolution`` metres.

    See the module docstring for the cell convention. The array is not copied on access;
    treat it as read-only (methods that change a grid return a new one).
    """

    prob: FloatArray
    resolution: float
    origin_xy: FloatArray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        prob = as_array(self.prob, "occupancy probabilities", (None, None))
        if np.any((prob < 0) | (prob > 1)):
            raise InputError("occupancy probabilities: expected values in [0, 1]")
        object.__setattr__(self, "prob", prob)
        object.__setattr__(self, "resolution", as_positive(self.resolution, "resolution"))
        object.__setattr__(self, "origin_xy", as_array(self.origin_xy, "origin_xy", (2,)))

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.prob.shape[0]), int(self.prob.shape[1]))

    @classmethod
    def empty(
        cls,
        xmin: float,
        ymin: float,
        xmax: float,
        ymax: float,
        resolution: float,
        value: float = UNKNOWN,
    ) -> OccupancyGrid:
        """A grid covering the box ``[xmin, xmax] × [ymin, ymax]`` filled with ``value``."""
        res = as_positive(resolution, "resolution")
        if not (xmax > xmin and ymax > ymin):
            raise InputError(
                f"grid bounds: expected xmax > xmin and ymax > ymin, got "
                f"({xmin}, {ymin}, {xmax}, {ymax})"
            )
        cols = int(np.ceil((xmax - xmin) / res))
        rows = int(np.ceil((ymax - ymin) / res))
        return cls(np.full((rows, cols), float(value)), res, np.array([xmin, ymin], float))

    def world_to_cell(self, xy: ArrayLike) -> NDArray[np.int64]:
        """Integer cells ``(..., 2)`` as ``(row, col)`` containing the points ``xy (..., 2)``
        (may lie outside the grid; see :meth:`contains`)."""
        p = np.asarray(xy, dtype=np.float64)
        col = np.floor((p[..., 0] - self.origin_xy[0]) / self.resolution)
        row = np.floor((p[..., 1] - self.origin_xy[1]) / self.resolution)
        return np.stack([row, col], axis=-1).astype(np.int64)

    def cell_to_world(self, cells: ArrayLike) -> FloatArray:
        """World coordinates ``(..., 2)`` of the centres of cells ``(..., 2)`` ``(row, col)``."""
        c = np.asarray(cells, dtype=np.float64)
        x = self.origin_xy[0] + (c[..., 1] + 0.5) * self.resolution
        y = self.origin_xy[1] + (c[..., 0] + 0.5) * self.resolution
        return np.stack([x, y], axis=-1)

    def contains(self, cells: ArrayLike) -> NDArray[np.bool_]:
        """Whether integer cells ``(..., 2)`` lie inside the grid."""
        c = np.asarray(cells)
        rows, cols = self.shape
        return (c[..., 0] >= 0) & (c[..., 0] < rows) & (c[..., 1] >= 0) & (c[..., 1] < cols)

    def occupied(self, threshold: float = OCCUPIED_THRESHOLD) -> NDArray[np.bool_]:
        """Boolean mask of cells whose probability is at least ``threshold``."""
        return self.prob >= threshold

    def free(self, threshold: float = FREE_THRESHOLD) -> NDArray[np.bool_]:
        """Boolean mask of cells whose probability is at most ``threshold``."""
        return self.prob <= threshold

    def bounds(self) -> tuple[float, float, float, float]:
        rows, cols = self.shape
        x0, y0 = float(self.origin_xy[0]), float(self.origin_xy[1])
        return (x0, y0, x0 + cols * self.resolution, y0 + rows * self.resolution)
