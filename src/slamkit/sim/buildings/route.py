"""The robot's route through a generated building: loops along the corridor grid, with
visits to rooms and crossings of halls, so that places are revisited and a SLAM system must
close loops.

The route is a polyline of waypoints for :func:`~slamkit.sim.follow_waypoints`:

1. from the bottom-left corridor crossing, once round the ring of corridors inside the outer
   wall (the big loop);
2. then moves drawn at random until a drawn target length (150-400 m of polyline) is reached,
   at least one:
   a loop round one block along its four corridors (revisiting stretches already driven), or
   a crossing of a hall from one opening to another;
3. back to the start crossing and on along the first corridor for half its length (the
   first place, revisited at the end).

Along every corridor stretch a room's door is visited with probability 0.3: the robot turns
in at the door, drives 1 m through it to the room's centre, turns and comes out the same
way. Every waypoint keeps to the corridors' centre lines, the doors' and openings' axes, and
the convex rooms and halls, so the straight lines between waypoints never meet a wall; the
clutter is placed afterwards, clear of the route. The polyline never exceeds 470 m, so the
driven path stays within 100-500 m.
"""

from __future__ import annotations

import numpy as np

from slamkit._validation import FloatArray
from slamkit.sim.buildings.layout import Doorway, Layout, Node

__all__ = ["ROUTE_CAP", "plan_route", "polyline_length"]

ROUTE_CAP = 470.0
"""Longest route polyline [m]."""

ROOM_VISIT_PROBABILITY = 0.3
"""Chance that the robot turns into a room whose door it passes."""


def polyline_length(points: FloatArray) -> float:
    """Length [m] of a polyline ``(W, 2)``."""
    return float(np.sum(np.hypot(*np.diff(points, axis=0).T)))


class _Planner:
    """Grows the route move by move; every move is planned in full, then kept only if the
    route with it and the way home still fits :data:`ROUTE_CAP`."""

    def __init__(self, layout: Layout, rng: np.random.Generator) -> None:
        self.layout = layout
        self.rng = rng
        self.node: Node = (0, 0)
        self.points: list[FloatArray] = [layout.node_xy(self.node)]
        self.length = 0.0
        self.doors: dict[frozenset[Node], list[Doorway]] = {}
        for d in layout.doorways:
            if d.kind == "door":
                self.doors.setdefault(frozenset(d.edge), []).append(d)

    def edge(self, a: Node, b: Node, visits: bool) -> list[FloatArray]:
        """Waypoints from node ``a`` to its neighbour ``b`` (``a`` excluded), with the doors
        along the way visited at random when ``visits``."""
        pa, pb = self.layout.node_xy(a), self.layout.node_xy(b)
        out: list[FloatArray] = []
        if visits:
            along = pb - pa
            doors = sorted(self.doors.get(frozenset((a, b)), []),
                           key=lambda d: float(np.dot(d.corridor - pa, along)))  # fmt: skip
            for d in doors:
                if self.rng.random() < ROOM_VISIT_PROBABILITY:
                    out += _room_visit(d)
        out.append(pb)
        return out

    def walk(self, start: Node, target: Node, visits: bool) -> tuple[list[FloatArray], Node]:
        """Waypoints along the corridors from ``start`` to ``target``: along x then y, or y
        then x (drawn)."""
        out: list[FloatArray] = []
        node = start
        order = (0, 1) if self.rng.random() < 0.5 else (1, 0)
        for axis in order:
            while node[axis] != target[axis]:
                step = 1 if target[axis] > node[axis] else -1
                nxt = (node[0] + step, node[1]) if axis == 0 else (node[0], node[1] + step)
                out += self.edge(node, nxt, visits)
                node = nxt
        return out, node

    def home_length(self, node: Node) -> float:
        """Length of the final leg from ``node``: back to the start, half a corridor on."""
        a = self.layout.node_xy(node)
        back = float(np.sum(np.abs(a - self.layout.node_xy((0, 0)))))
        return back + 0.5 * float(self.layout.xs[1] - self.layout.xs[0])

    def commit(self, points: list[FloatArray], end: Node, force: bool = False) -> bool:
        if not points:
            return True
        added = polyline_length(np.vstack([self.points[-1], *points]))
        if not force and self.length + added + self.home_length(end) > ROUTE_CAP:
            return False
        self.points += points
        self.length += added
        self.node = end
        return True

    def ring(self) -> None:
        nx, ny = self.layout.nx, self.layout.ny
        corners: list[Node] = [(nx, 0), (nx, ny), (0, ny), (0, 0)]
        pts: list[FloatArray] = []
        node: Node = (0, 0)
        for corner in corners:
            leg, node = self.walk(node, corner, visits=True)
            pts += leg
        self.commit(pts, node, force=True)

    def block_loop(self) -> None:
        """Round a random block along its four corridors, from its nearest corner."""
        ix, iy = int(self.rng.integers(self.layout.nx)), int(self.rng.integers(self.layout.ny))
        loop: list[Node] = [(ix, iy), (ix + 1, iy), (ix + 1, iy + 1), (ix, iy + 1)]
        if self.rng.random() < 0.5:
            loop.reverse()
        here = self.layout.node_xy(self.node)
        first = min(
            range(4), key=lambda i: float(np.sum(np.abs(self.layout.node_xy(loop[i]) - here)))
        )
        loop = loop[first:] + loop[:first]
        pts, node = self.walk(self.node, loop[0], visits=False)
        for a, b in zip(loop, [*loop[1:], loop[0]], strict=True):
            pts += self.edge(a, b, visits=True)
        self.commit(pts, node)

    def hall_crossing(self) -> None:
        """Into a hall by one opening, past a point or two inside, out by another."""
        by_hall: dict[tuple[float, ...], list[Doorway]] = {}
        for d in self.layout.doorways:
            if d.kind == "opening":
                by_hall.setdefault(d.region, []).append(d)
        halls = list(by_hall.values())
        openings = halls[int(self.rng.integers(len(halls)))]
        i, j = self.rng.choice(len(openings), size=2, replace=False)
        d_in, d_out = openings[int(i)], openings[int(j)]
        start = d_in.edge[int(self.rng.integers(2))]
        pts, _ = self.walk(self.node, start, visits=False)
        x0, y0, x1, y1 = d_in.region
        inner = [
            np.array([self.rng.uniform(x0 + 2.0, x1 - 2.0), self.rng.uniform(y0 + 2.0, y1 - 2.0)])
            for _ in range(int(self.rng.integers(1, 3)))
        ]
        pts += [d_in.corridor, d_in.inside(1.5), *inner, d_out.inside(1.5), d_out.corridor]
        end = d_out.edge[int(self.rng.integers(2))]
        pts.append(self.layout.node_xy(end))
        self.commit(pts, end)

    def home(self) -> None:
        pts, node = self.walk(self.node, (0, 0), visits=False)
        half = 0.5 * (self.layout.node_xy((0, 0)) + self.layout.node_xy((1, 0)))
        self.commit([*pts, half], node, force=True)


def _room_visit(door: Doorway) -> list[FloatArray]:
    """In at ``door`` to its room's centre and out again."""
    x0, y0, x1, y1 = door.region
    centre = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1)])
    return [door.corridor, door.inside(1.0), centre, door.inside(1.0), door.corridor]


def plan_route(layout: Layout, rng: np.random.Generator) -> FloatArray:
    """The route's waypoints ``(W, 2)`` from the start crossing (see the module docstring)."""
    planner = _Planner(layout, rng)
    target = float(rng.uniform(150.0, 400.0))
    planner.ring()
    ring = len(planner.points)
    for _ in range(40):  # at least one move after the ring, so a lap is driven again
        if planner.length >= target and len(planner.points) > ring:
            break
        if rng.random() < 0.35 and any(d.kind == "opening" for d in layout.doorways):
            planner.hall_crossing()
        else:
            planner.block_loop()
    planner.home()
    route = np.asarray(planner.points)
    keep = np.ones(len(route), dtype=bool)  # drop repeated waypoints (zero-length legs)
    keep[1:] = np.hypot(*np.diff(route, axis=0).T) > 1e-9
    return route[keep]
