"""The floor plan of a generated building: a grid of blocks between corridors.

The plan is ``nx × ny`` blocks (2-4 columns, 1-2 rows) laid out on a grid of corridors 2-3 m
wide: a corridor runs all round the building inside its outer wall and between every two
neighbouring blocks, so the corridors form a grid graph whose nodes are their crossings.
A block is either

* **offices**: one or two rows of rooms 3.5-8 m wide, each with one door of 1.0-1.4 m onto
  the corridor along its row's outer side; some rooms have a glass front; or
* an **open hall**: its perimeter has 2-4 openings of 2.5-4 m onto the corridors, and about
  a third of the perimeter is glass.

The outer wall has glass windows. Every length is rounded to 5 cm. Walls are segments of
zero thickness; block perimeters, partitions and the outer wall never overlap (blocks are
separated by corridors). Everything is drawn from the ``np.random.Generator`` passed in.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Literal

import numpy as np

from slamkit._validation import FloatArray

__all__ = ["Block", "Doorway", "Layout", "draw_layout", "side_segments"]

Side = Literal["bottom", "top", "left", "right"]
Node = tuple[int, int]

GLASS_WINDOW_SHARE = 0.35
"""Share of the outer wall's 4 m panels that hold a 2 m glass window."""


def _q(x: float) -> float:
    """Round to 5 cm, so plans print and compare cleanly."""
    return round(x * 20.0) / 20.0


@dataclass(frozen=True)
class Doorway:
    """A gap in a block's perimeter: a room's door or a hall's opening.

    ``centre (2,)`` on the wall line, ``width`` [m], ``inward (2,)`` the unit normal into the
    block, ``region`` the rectangle ``(x0, y0, x1, y1)`` it leads into (the room or the
    hall), ``edge`` the corridor edge (two grid nodes) it opens onto, ``corridor (2,)`` the
    point on that corridor's centre line in front of it.
    """

    kind: Literal["door", "opening"]
    centre: FloatArray
    width: float
    inward: FloatArray
    region: tuple[float, float, float, float]
    edge: tuple[Node, Node]
    corridor: FloatArray

    def inside(self, depth: float) -> FloatArray:
        """The point ``depth`` metres in from the gap, on its axis."""
        return self.centre + depth * self.inward


@dataclass(frozen=True)
class Block:
    """One block of the grid: its rectangle, its kind and, for offices, its rooms."""

    ix: int
    iy: int
    rect: tuple[float, float, float, float]
    kind: Literal["offices", "hall"]
    rooms: tuple[tuple[float, float, float, float], ...] = ()


@dataclass(frozen=True)
class Layout:
    """The drawn plan: corridor centre lines ``xs (nx + 1,)`` and ``ys (ny + 1,)`` (their
    crossings are the grid nodes), corridor widths, the outer size, the blocks, the
    doorways, and the walls split into opaque ``walls (S, 2, 2)`` and ``glass (G, 2, 2)``."""

    xs: FloatArray
    ys: FloatArray
    corridor_x: FloatArray
    corridor_y: FloatArray
    size: tuple[float, float]
    blocks: tuple[Block, ...]
    doorways: tuple[Doorway, ...]
    walls: FloatArray
    glass: FloatArray

    @property
    def nx(self) -> int:
        return int(self.xs.size - 1)

    @property
    def ny(self) -> int:
        return int(self.ys.size - 1)

    def node_xy(self, node: Node) -> FloatArray:
        return np.array([self.xs[node[0]], self.ys[node[1]]])

    def block(self, ix: int, iy: int) -> Block:
        return self.blocks[iy * self.nx + ix]


def side_segments(
    a: FloatArray,
    b: FloatArray,
    gaps: list[tuple[float, float]],
    glass: list[tuple[float, float]],
) -> tuple[list[FloatArray], list[FloatArray]]:
    """The wall from ``a`` to ``b`` with ``gaps`` left open and ``glass`` stretches glazed
    (intervals in metres from ``a``): the opaque and the glass segments ``(2, 2)``, each run
    of one material merged into one segment."""
    length = float(np.hypot(*(b - a)))
    cuts = sorted({0.0, length, *(min(max(s, 0.0), length) for iv in gaps + glass for s in iv)})
    opaque: list[FloatArray] = []
    glazed: list[FloatArray] = []
    runs: list[tuple[str, float, float]] = []
    for s0, s1 in itertools.pairwise(cuts):
        if s1 - s0 < 1e-9:
            continue
        mid = 0.5 * (s0 + s1)
        if any(lo <= mid <= hi for lo, hi in gaps):
            kind = "gap"
        elif any(lo <= mid <= hi for lo, hi in glass):
            kind = "glass"
        else:
            kind = "wall"
        if runs and runs[-1][0] == kind and abs(runs[-1][2] - s0) < 1e-9:
            runs[-1] = (kind, runs[-1][1], s1)
        else:
            runs.append((kind, s0, s1))
    direction = (b - a) / length
    for kind, s0, s1 in runs:
        seg = np.stack([a + s0 * direction, a + s1 * direction])
        if kind == "wall":
            opaque.append(seg)
        elif kind == "glass":
            glazed.append(seg)
    return opaque, glazed


def _corners(rect: tuple[float, float, float, float]) -> dict[Side, tuple[FloatArray, FloatArray]]:
    x0, y0, x1, y1 = rect
    return {
        "bottom": (np.array([x0, y0]), np.array([x1, y0])),
        "top": (np.array([x0, y1]), np.array([x1, y1])),
        "left": (np.array([x0, y0]), np.array([x0, y1])),
        "right": (np.array([x1, y0]), np.array([x1, y1])),
    }


_INWARD: dict[Side, tuple[float, float]] = {
    "bottom": (0.0, 1.0),
    "top": (0.0, -1.0),
    "left": (1.0, 0.0),
    "right": (-1.0, 0.0),
}


def _edge_of(ix: int, iy: int, side: Side) -> tuple[Node, Node]:
    """The corridor edge (two grid nodes) a block side faces."""
    if side == "bottom":
        return (ix, iy), (ix + 1, iy)
    if side == "top":
        return (ix, iy + 1), (ix + 1, iy + 1)
    if side == "left":
        return (ix, iy), (ix, iy + 1)
    return (ix + 1, iy), (ix + 1, iy + 1)


def draw_layout(rng: np.random.Generator) -> Layout:
    """Draw a plan (see the module docstring)."""
    nx = int(rng.integers(2, 5))
    ny = int(rng.integers(1, 3))
    widths = [_q(rng.uniform(9.0, 16.0)) for _ in range(nx)]
    heights = [_q(rng.uniform(8.0, 13.0)) for _ in range(ny)]
    corridor_x = np.array([rng.choice([2.0, 2.5, 3.0]) for _ in range(nx + 1)])
    corridor_y = np.array([rng.choice([2.0, 2.5, 3.0]) for _ in range(ny + 1)])
    # Corridor i spans [e, e + c_i]; block i follows it.
    xs, bx = _lay_out(corridor_x, widths)
    ys, by = _lay_out(corridor_y, heights)
    size = (float(bx[-1][1] + corridor_x[-1]), float(by[-1][1] + corridor_y[-1]))

    n_blocks = nx * ny
    n_halls = 1 if n_blocks <= 3 else int(rng.integers(1, 3))
    halls = set(rng.choice(n_blocks, size=n_halls, replace=False).tolist())
    walls: list[FloatArray] = []
    glass: list[FloatArray] = []
    blocks: list[Block] = []
    doorways: list[Doorway] = []
    for iy in range(ny):
        for ix in range(nx):
            rect = (bx[ix][0], by[iy][0], bx[ix][1], by[iy][1])
            centre_line: dict[Side, float] = {
                "bottom": ys[iy],
                "top": ys[iy + 1],
                "left": xs[ix],
                "right": xs[ix + 1],
            }
            if iy * nx + ix in halls:
                block, doors = _hall(ix, iy, rect, centre_line, rng, walls, glass)
            else:
                block, doors = _offices(ix, iy, rect, centre_line, rng, walls, glass)
            blocks.append(block)
            doorways += doors
    _outer_wall(size, rng, walls, glass)
    return Layout(
        xs=np.asarray(xs),
        ys=np.asarray(ys),
        corridor_x=corridor_x,
        corridor_y=corridor_y,
        size=size,
        blocks=tuple(blocks),
        doorways=tuple(doorways),
        walls=np.asarray(walls, dtype=float).reshape(-1, 2, 2),
        glass=np.asarray(glass, dtype=float).reshape(-1, 2, 2),
    )


def _lay_out(
    corridors: FloatArray, blocks: list[float]
) -> tuple[list[float], list[tuple[float, float]]]:
    """Corridor centre lines and block extents along one axis, from 0."""
    centres: list[float] = []
    extents: list[tuple[float, float]] = []
    e = 0.0
    for i, c in enumerate(corridors):
        centres.append(e + c / 2.0)
        e += c
        if i < len(blocks):
            extents.append((e, e + blocks[i]))
            e += blocks[i]
    return centres, extents


def _doorway(
    kind: Literal["door", "opening"],
    ix: int,
    iy: int,
    side: Side,
    along: float,
    width: float,
    region: tuple[float, float, float, float],
    rect: tuple[float, float, float, float],
    centre_line: dict[Side, float],
) -> Doorway:
    """The doorway centred ``along`` metres from the side's first corner."""
    a, b = _corners(rect)[side]
    centre = a + along * (b - a) / np.hypot(*(b - a))
    corridor = centre.copy()
    axis = 1 if side in ("bottom", "top") else 0
    corridor[axis] = centre_line[side]
    return Doorway(
        kind, centre, width, np.array(_INWARD[side]), region, _edge_of(ix, iy, side), corridor
    )


def _hall(
    ix: int,
    iy: int,
    rect: tuple[float, float, float, float],
    centre_line: dict[Side, float],
    rng: np.random.Generator,
    walls: list[FloatArray],
    glass: list[FloatArray],
) -> tuple[Block, list[Doorway]]:
    """An open hall: 2-4 openings of 2.5-4 m, a third of its perimeter glass."""
    sides: list[Side] = ["bottom", "top", "left", "right"]
    n_open = int(rng.integers(2, 5))
    open_sides = set(rng.choice(4, size=n_open, replace=False).tolist())
    doors: list[Doorway] = []
    for i, side in enumerate(sides):
        a, b = _corners(rect)[side]
        length = float(np.hypot(*(b - a)))
        gaps: list[tuple[float, float]] = []
        if i in open_sides:
            width = _q(rng.uniform(2.5, 4.0))
            along = _q(rng.uniform(1.0 + width / 2.0, length - 1.0 - width / 2.0))
            gaps.append((along - width / 2.0, along + width / 2.0))
            doors.append(_doorway("opening", ix, iy, side, along, width, rect, rect, centre_line))
        panes = []
        for s0 in np.arange(0.0, length - 1e-9, 3.0):
            if rng.random() < 0.35:
                panes.append((float(s0), float(min(s0 + 3.0, length))))
        opaque, glazed = side_segments(a, b, gaps, panes)
        walls += opaque
        glass += glazed
    return Block(ix, iy, rect, "hall"), doors


def _offices(
    ix: int,
    iy: int,
    rect: tuple[float, float, float, float],
    centre_line: dict[Side, float],
    rng: np.random.Generator,
    walls: list[FloatArray],
    glass: list[FloatArray],
) -> tuple[Block, list[Doorway]]:
    """One or two rows of rooms with a door each onto the corridor along the row."""
    x0, y0, x1, y1 = rect
    two_rows = (y1 - y0) >= 9.0
    mid = _q(0.5 * (y0 + y1)) if two_rows else y1
    rows: list[tuple[float, float, Side]]
    if two_rows:
        walls.append(np.array([[x0, mid], [x1, mid]]))
        rows = [(y0, mid, "bottom"), (mid, y1, "top")]
    else:
        rows = [(y0, y1, "bottom" if rng.random() < 0.5 else "top")]
    gaps: dict[Side, list[tuple[float, float]]] = {
        s: [] for s in ("bottom", "top", "left", "right")
    }
    panes: dict[Side, list[tuple[float, float]]] = {s: [] for s in gaps}
    doors: list[Doorway] = []
    rooms: list[tuple[float, float, float, float]] = []
    for r0, r1, side in rows:
        n_rooms = max(2, int((x1 - x0) / rng.uniform(3.5, 5.5)))
        cuts = np.linspace(x0, x1, n_rooms + 1)  # rooms >= 4.5 m before the jitter
        jitter = rng.uniform(-0.4, 0.4, n_rooms - 1)
        cuts[1:-1] = [_q(c + j) for c, j in zip(cuts[1:-1], jitter, strict=True)]
        for c in cuts[1:-1]:
            walls.append(np.array([[c, r0], [c, r1]]))
        for a, b in itertools.pairwise(cuts):
            room = (float(a), r0, float(b), r1)
            rooms.append(room)
            width = _q(rng.uniform(1.0, 1.4))
            along = _q(rng.uniform(a - x0 + 0.4 + width / 2.0, b - x0 - 0.4 - width / 2.0))
            gaps[side].append((along - width / 2.0, along + width / 2.0))
            doors.append(_doorway("door", ix, iy, side, along, width, room, rect, centre_line))
            if rng.random() < 0.25:  # a glass front
                panes[side].append((float(a - x0), float(b - x0)))
    for side, (a_pt, b_pt) in _corners(rect).items():
        opaque, glazed = side_segments(a_pt, b_pt, gaps[side], panes[side])
        walls += opaque
        glass += glazed
    return Block(ix, iy, rect, "offices", tuple(rooms)), doors


def _outer_wall(
    size: tuple[float, float],
    rng: np.random.Generator,
    walls: list[FloatArray],
    glass: list[FloatArray],
) -> None:
    """The building's outer wall, with a 2 m window in some of its 4 m panels."""
    for a, b in _corners((0.0, 0.0, size[0], size[1])).values():
        length = float(np.hypot(*(b - a)))
        panes = [
            (float(s0 + 1.0), float(min(s0 + 3.0, length)))
            for s0 in np.arange(0.0, length - 4.0, 4.0)
            if rng.random() < GLASS_WINDOW_SHARE
        ]
        opaque, glazed = side_segments(a, b, [], panes)
        walls += opaque
        glass += glazed
