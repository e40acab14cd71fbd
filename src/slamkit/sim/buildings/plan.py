"""A generated building: floor plan, clutter, glass, walking people and the robot's route,
all drawn from one seed.

:func:`generate_building` draws the plan (:mod:`~slamkit.sim.buildings.layout`), the route
(:mod:`~slamkit.sim.buildings.route`), then the clutter clear of the route:

* in halls, a grid of pillars (0.4-0.6 m square, 3.5-5 m apart) and 2-5 boxes
  (0.4-1.2 m sides);
* in rooms, 0-2 boxes against the walls;
* in corridors, boxes 0.4-0.6 m along and 0.2-0.4 m deep against the walls, about one per
  6 m;

a piece of clutter is dropped when it would stand within 0.8 m of the route, within 0.6 m
of a doorway's gap or within 0.3 m of other clutter, or reach outside its room, hall or
corridor. Then 3-6 people, each walking to and fro at 0.5-1.3 m/s along a corridor (0.5 m
off its centre line) or between two points of a hall.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from slamkit._validation import FloatArray
from slamkit.maps import SegmentMap
from slamkit.sim.buildings.layout import Layout, draw_layout
from slamkit.sim.buildings.route import plan_route, polyline_length
from slamkit.sim.worlds import rectangle_segments

__all__ = ["Building", "Walkers", "generate_building"]

ROUTE_CLEARANCE = 0.8
"""Least distance [m] from the route polyline to any clutter."""
PERSON_RADIUS = 0.25
"""Radius [m] of the circle a walking person shows the laser."""


@dataclass(frozen=True)
class Walkers:
    """People walking to and fro: person ``i`` goes from ``ends[i, 0]`` to ``ends[i, 1]``
    and back at ``speeds[i]`` [m/s], starting ``phases[i]`` metres along the way; each is a
    circle of ``radius`` [m]."""

    ends: FloatArray
    speeds: FloatArray
    phases: FloatArray
    radius: float = PERSON_RADIUS

    def positions(self, times: FloatArray) -> FloatArray:
        """Centres ``(T, P, 2)`` at ``times (T,)`` [s] (a triangle wave along each line)."""
        t = np.asarray(times, dtype=float)[:, None]
        span = np.hypot(*(self.ends[:, 1] - self.ends[:, 0]).T)[None, :]
        s = np.mod(self.phases[None, :] + self.speeds[None, :] * t, 2.0 * span)
        s = np.where(s > span, 2.0 * span - s, s) / np.where(span > 0, span, 1.0)
        return self.ends[None, :, 0] + s[..., None] * (
            self.ends[None, :, 1] - self.ends[None, :, 0]
        )


@dataclass(frozen=True, eq=False)
class Building:
    """A generated building.

    * ``walls``: the opaque walls and the clutter (segments the laser always sees);
    * ``glass``: glass panes (the laser sees them only at times; see
      :mod:`slamkit.sim.buildings.scans`);
    * ``route (W, 2)``: waypoints the robot drives through in order, from ``start (3,)``;
    * ``walkers``: the people (not part of the static map);
    * ``layout``: the plan the walls came from (corridors, blocks, doorways).
    """

    seed: int
    walls: SegmentMap
    glass: SegmentMap
    route: FloatArray
    start: FloatArray
    walkers: Walkers
    layout: Layout

    @property
    def static_map(self) -> SegmentMap:
        """Every static segment, glass included (the true map)."""
        return SegmentMap(np.concatenate([self.walls.segments, self.glass.segments]))

    @property
    def route_length(self) -> float:
        """Length [m] of the route polyline."""
        return polyline_length(self.route)

    def describe(self) -> str:
        halls = sum(b.kind == "hall" for b in self.layout.blocks)
        rooms = sum(len(b.rooms) for b in self.layout.blocks)
        w, h = self.layout.size
        return (
            f"building {self.seed}: {w:.0f} m × {h:.0f} m, {rooms} rooms, {halls} "
            f"hall{'s' if halls != 1 else ''}, a {self.route_length:.0f} m route of loops"
        )


def generate_building(seed: int) -> Building:
    """The building of ``seed`` (see the module docstring); same seed, same building."""
    rng = np.random.default_rng(seed)
    layout = draw_layout(rng)
    route = plan_route(layout, rng)
    samples = _densify(route, 0.1)
    clutter = _clutter(layout, samples, rng)
    walls = np.concatenate([layout.walls, *[rectangle_segments(*r) for r in clutter]])
    start_heading = float(np.arctan2(*(route[1] - route[0])[::-1]))
    return Building(
        seed=int(seed),
        walls=SegmentMap(walls),
        glass=SegmentMap(layout.glass),
        route=route,
        start=np.array([route[0, 0], route[0, 1], start_heading]),
        walkers=_walkers(layout, rng),
        layout=layout,
    )


def _densify(route: FloatArray, step: float) -> FloatArray:
    """Points along the polyline at most ``step`` metres apart."""
    out = [route[:1]]
    for a, b in itertools.pairwise(route):
        n = max(1, int(np.ceil(np.hypot(*(b - a)) / step)))
        out.append(a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a))
    return np.concatenate(out)


def _rect_distance(rect: tuple[float, float, float, float], points: FloatArray) -> FloatArray:
    """Distances from ``points (N, 2)`` to an axis-aligned rectangle (0 inside)."""
    x0, y0, x1, y1 = rect
    dx = np.maximum(np.maximum(x0 - points[:, 0], points[:, 0] - x1), 0.0)
    dy = np.maximum(np.maximum(y0 - points[:, 1], points[:, 1] - y1), 0.0)
    return np.hypot(dx, dy)


def _gap(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    """Distance between two axis-aligned rectangles."""
    dx = max(a[0] - b[2], b[0] - a[2], 0.0)
    dy = max(a[1] - b[3], b[1] - a[3], 0.0)
    return float(np.hypot(dx, dy))


def _clutter(
    layout: Layout, route: FloatArray, rng: np.random.Generator
) -> list[tuple[float, float, float, float]]:
    """Boxes and pillars ``(x0, y0, x1, y1)`` clear of the route and the doorways."""
    placed: list[tuple[float, float, float, float]] = []
    door_pts = np.array([d.centre for d in layout.doorways]).reshape(-1, 2)
    door_half = np.array([d.width / 2.0 for d in layout.doorways])

    def place(rect: tuple[float, float, float, float], region: tuple[float, ...]) -> None:
        x0, y0, x1, y1 = rect
        if x0 < region[0] or y0 < region[1] or x1 > region[2] or y1 > region[3]:
            return
        if np.min(_rect_distance(rect, route)) < ROUTE_CLEARANCE:
            return
        if door_pts.size and np.any(_rect_distance(rect, door_pts) < door_half + 0.6):
            return
        if any(_gap(rect, other) < 0.3 for other in placed):
            return
        placed.append(tuple(round(v, 3) for v in rect))  # type: ignore[arg-type]

    for block in layout.blocks:
        x0, y0, x1, y1 = block.rect
        inner = (x0 + 0.05, y0 + 0.05, x1 - 0.05, y1 - 0.05)
        if block.kind == "hall":
            spacing = rng.uniform(3.5, 5.0)
            half = rng.uniform(0.2, 0.3)
            for cx in np.arange(x0 + 2.0, x1 - 1.5, spacing):
                for cy in np.arange(y0 + 2.0, y1 - 1.5, spacing):
                    place((cx - half, cy - half, cx + half, cy + half), inner)
            for _ in range(int(rng.integers(2, 6))):
                hx, hy = rng.uniform(0.2, 0.6, 2)
                cx, cy = rng.uniform(x0 + 0.3 + hx, x1 - 0.3 - hx), rng.uniform(y0 + 0.3, y1 - 0.3)
                place((cx - hx, cy - hy, cx + hx, cy + hy), inner)
        for room in block.rooms:
            for _ in range(int(rng.integers(0, 3))):
                place(_against_wall(room, rng, (0.3, 0.8), (0.25, 0.5)), _shrink(room, 0.05))
    # Corridors: the strips between the outer wall and the blocks, and between blocks.
    width, height = layout.size
    for i, x in enumerate(layout.xs):
        c = layout.corridor_x[i] / 2.0
        strip = (x - c, 0.0, x + c, height)
        for _ in range(max(1, round(height / 6.0))):
            place(
                _against_wall(strip, rng, (0.2, 0.3), (0.1, 0.2), sides=(2, 3)),
                _shrink(strip, 0.05),
            )
    for j, y in enumerate(layout.ys):
        c = layout.corridor_y[j] / 2.0
        strip = (0.0, y - c, width, y + c)
        for _ in range(max(1, round(width / 6.0))):
            place(
                _against_wall(strip, rng, (0.2, 0.3), (0.1, 0.2), sides=(0, 1)),
                _shrink(strip, 0.05),
            )
    return placed


def _shrink(rect: tuple[float, float, float, float], m: float) -> tuple[float, float, float, float]:
    return (rect[0] + m, rect[1] + m, rect[2] - m, rect[3] - m)


def _against_wall(
    region: tuple[float, float, float, float],
    rng: np.random.Generator,
    half_along: tuple[float, float],
    half_depth: tuple[float, float],
    sides: tuple[int, ...] = (0, 1, 2, 3),
) -> tuple[float, float, float, float]:
    """A box 5 cm off one of the region's walls (0 bottom, 1 top, 2 left, 3 right), at a
    random place along it."""
    x0, y0, x1, y1 = _shrink(region, 0.05)
    ha, hd = rng.uniform(*half_along), rng.uniform(*half_depth)
    side = sides[int(rng.integers(len(sides)))]
    if side in (0, 1):
        cx = rng.uniform(x0 + ha, max(x0 + ha, x1 - ha))
        cy = y0 + hd if side == 0 else y1 - hd
        return (cx - ha, cy - hd, cx + ha, cy + hd)
    cy = rng.uniform(y0 + ha, max(y0 + ha, y1 - ha))
    cx = x0 + hd if side == 2 else x1 - hd
    return (cx - hd, cy - ha, cx + hd, cy + ha)


def _walkers(layout: Layout, rng: np.random.Generator) -> Walkers:
    """3-6 people along corridors or across halls."""
    n = int(rng.integers(3, 7))
    halls = [b.rect for b in layout.blocks if b.kind == "hall"]
    ends = np.zeros((n, 2, 2))
    for i in range(n):
        if halls and rng.random() < 0.35:
            x0, y0, x1, y1 = halls[int(rng.integers(len(halls)))]
            ends[i] = rng.uniform([x0 + 1.0, y0 + 1.0], [x1 - 1.0, y1 - 1.0], (2, 2))
        elif rng.random() < 0.5:  # along a vertical corridor
            x = layout.xs[int(rng.integers(layout.xs.size))] + rng.choice([-0.5, 0.5])
            ends[i] = [[x, 1.0], [x, layout.size[1] - 1.0]]
        else:
            y = layout.ys[int(rng.integers(layout.ys.size))] + rng.choice([-0.5, 0.5])
            ends[i] = [[1.0, y], [layout.size[0] - 1.0, y]]
    span = np.hypot(*(ends[:, 1] - ends[:, 0]).T)
    return Walkers(ends, rng.uniform(0.5, 1.3, n), rng.uniform(0.0, 2.0, n) * span)
