"""Simulated laser worlds that need loop closure.

* ``corridor-loop-laser``: the robot drives once round a 30 m × 20 m ring of 2.5 m wide
  corridors and on past its start, so it re-enters the first corridor after about 100 m of
  path. Boxes stand along the walls at irregular spacings, so scan matching has something
  to hold on to along the corridors and a revisited stretch can be recognised; between them
  the walls are bare, so matching alone drifts and odometry noise adds up.
* ``long-hallway-laser``: a 50 m hallway, 2.4 m wide, between two 5 m × 5 m rooms, driven
  from the first room to the second, round it, and back. Along most of the hallway the
  walls are bare and parallel, so the scans fix the robot across the hallway and in
  heading but not along it (scan matching reports degenerate geometry there and the
  odometry carries the pose); only a few pillars and the rooms' furniture pin it down. On
  the way back the first room is re-entered with the drift the hallway let through, and
  the closures there must pull it out.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.stream import Control, Dataset, Event, GroundTruth, LaserScan, MotionSpec
from slamkit.maps import SegmentMap
from slamkit.models import UnicycleEuler
from slamkit.sim.scenarios import LaserScenarioConfig
from slamkit.sim.sensors import simulate_scan
from slamkit.sim.trajectory import follow_waypoints
from slamkit.sim.worlds import rasterize_segments, rectangle_segments

__all__ = ["build_corridor_loop", "build_long_hallway", "corridor_loop_world", "long_hallway_world"]

# Boxes (centre x, centre y, half side) along the walls; positions chosen irregular so no
# two stretches of corridor look alike.
_BOXES = (
    (4.0, 0.25, 0.25), (9.5, 0.2, 0.2), (13.0, 2.55, 0.3), (17.5, 0.3, 0.3), (22.0, 2.7, 0.2),
    (26.5, 0.25, 0.25), (29.75, 5.0, 0.25), (27.2, 8.5, 0.2), (29.7, 12.0, 0.3),
    (27.3, 15.5, 0.3), (24.0, 19.75, 0.25), (19.0, 17.25, 0.25), (15.5, 19.7, 0.3),
    (10.0, 17.3, 0.3), (6.5, 19.8, 0.2), (2.75, 17.5, 0.25), (0.25, 13.0, 0.25),
    (2.7, 9.0, 0.2), (0.3, 5.5, 0.3),
)  # fmt: skip


def corridor_loop_world() -> SegmentMap:
    """Walls of the ring: the outer rectangle 30 m × 20 m, the inner block 2.5 m in from
    it on every side, and the boxes of :data:`_BOXES`."""
    walls = [*rectangle_segments(0.0, 0.0, 30.0, 20.0), *rectangle_segments(2.5, 2.5, 27.5, 17.5)]
    for cx, cy, h in _BOXES:
        walls += list(rectangle_segments(cx - h, cy - h, cx + h, cy + h))
    return SegmentMap(np.asarray(walls, dtype=float))


# Pillars along the hallway's walls and furniture in the two end rooms (centre x, centre
# y, half side): the hallway between x = 0 and 50 m is bare but for four pillars.
_HALLWAY_BOXES = (
    (7.0, 0.2, 0.2), (19.5, 2.2, 0.2), (31.0, 0.2, 0.2), (44.0, 2.2, 0.2),
    (-4.2, -0.6, 0.4), (-1.2, 3.1, 0.3), (-4.5, 2.8, 0.25),
    (54.3, 3.0, 0.4), (51.0, -0.8, 0.3), (53.6, -0.5, 0.25),
)  # fmt: skip


def long_hallway_world() -> SegmentMap:
    """Walls of the hallway (x in [0, 50] m, y in [0, 2.4] m), the rooms at its ends
    (x in [-5, 0] and [50, 55] m, y in [-1.3, 3.7] m) and the boxes of
    :data:`_HALLWAY_BOXES`."""
    ends = [
        (0.0, 0.0, 50.0, 0.0), (0.0, 2.4, 50.0, 2.4),
        (0.0, 0.0, 0.0, -1.3), (0.0, -1.3, -5.0, -1.3), (-5.0, -1.3, -5.0, 3.7),
        (-5.0, 3.7, 0.0, 3.7), (0.0, 3.7, 0.0, 2.4),
        (50.0, 0.0, 50.0, -1.3), (50.0, -1.3, 55.0, -1.3), (55.0, -1.3, 55.0, 3.7),
        (55.0, 3.7, 50.0, 3.7), (50.0, 3.7, 50.0, 2.4),
    ]  # fmt: skip
    walls = list(np.asarray(ends, dtype=float).reshape(-1, 2, 2))
    for cx, cy, h in _HALLWAY_BOXES:
        walls += list(rectangle_segments(cx - h, cy - h, cx + h, cy + h))
    return SegmentMap(np.asarray(walls, dtype=float))


def build_corridor_loop(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """The ring of corridors driven once round and 10 m on past the start (a
    :class:`LaserScenarioConfig` in ``options``; the true occupancy grid is the walls
    rasterised)."""
    cfg = config_from_mapping(LaserScenarioConfig, options, "scenario")
    c = 1.25  # the corridors' centre lines
    lap = np.array([[30.0 - c, c], [30.0 - c, 20.0 - c], [c, 20.0 - c], [c, c]])
    waypoints = np.vstack([np.tile(lap, (cfg.laps, 1)), [[15.0, c]]])
    return _drive(
        cfg, seed, corridor_loop_world(), np.array([5.0, c, 0.0]), waypoints,
        "corridor-loop-laser",
        "laser drive round a 30 m × 20 m ring of corridors and on past the start",
    )  # fmt: skip


def build_long_hallway(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """The long hallway driven from the first room to the second, round it, and back
    (``laps`` times; a :class:`LaserScenarioConfig` in ``options``)."""
    cfg = config_from_mapping(LaserScenarioConfig, options, "scenario")
    c = 1.2  # the hallway's centre line
    there_and_back = np.array(
        [[51.5, c], [53.5, 0.2], [53.8, 2.2], [51.5, c], [-1.5, c], [-3.5, 2.3], [-3.6, 0.2]]
    )
    waypoints = np.vstack([np.tile(there_and_back, (cfg.laps, 1)), [[-1.0, c]]])
    return _drive(
        cfg, seed, long_hallway_world(), np.array([-2.5, c, 0.0]), waypoints,
        "long-hallway-laser",
        "laser drive down a bare 50 m hallway between two rooms and back",
    )  # fmt: skip


def _drive(
    cfg: LaserScenarioConfig,
    seed: int,
    walls: SegmentMap,
    start: np.ndarray,
    waypoints: np.ndarray,
    name: str,
    description: str,
) -> Dataset:
    """The data set of a unicycle driven through ``waypoints`` from ``start`` among
    ``walls``: noisy controls, a scan per step, the truth and the rasterised walls."""
    rng = np.random.default_rng(seed)
    model = UnicycleEuler()
    q = np.diag([cfg.sigma_v**2, np.deg2rad(cfg.sigma_omega_deg) ** 2])
    drive = follow_waypoints(
        start, waypoints, speed=cfg.speed, dt=cfg.dt, control_cov=q, rng=rng, tolerance=0.3
    )
    truth = drive.poses
    times = cfg.dt * np.arange(truth.shape[0], dtype=np.float64)
    laser = cfg.laser_spec()
    events: list[Event] = []
    for k in range(truth.shape[0]):
        if k > 0:
            events.append(Control(float(times[k]), drive.controls[k - 1], cfg.dt))
        events.append(LaserScan(float(times[k]), simulate_scan(truth[k], walls, laser, rng)))
    grid = rasterize_segments(walls, cfg.grid_resolution, padding=0.5)
    s, st = cfg.initial_sigma_xy, np.deg2rad(cfg.initial_sigma_theta_deg)
    return Dataset(
        name=name,
        events=tuple(events),
        motion=MotionSpec(model, q),
        laser=laser,
        initial_pose=start,
        initial_cov=np.diag([s**2, s**2, st**2]),
        known_grid=grid,
        truth=GroundTruth(times=times, poses=truth, walls=walls, occupancy=grid),
        description=description,
        metadata={"kind": "simulated"},
        provenance=Provenance(options=config_to_dict(cfg)),
    )
