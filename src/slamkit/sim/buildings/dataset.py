"""Generated buildings as data sets: the route driven, scans, odometry and the truth.

:func:`build_building_dataset` drives the route of :func:`generate_building` with the
closed-loop waypoint follower (:func:`~slamkit.sim.follow_waypoints`, a 5 Hz control loop
with small execution noise, so the true path wiggles as a real robot's does) and keeps a
scan, like the corrected CARMEN logs, each time the robot has moved
:attr:`BuildingConfig.scan_spacing` metres or turned :attr:`BuildingConfig.scan_turn_deg`
since the last one: a pose-gated log, not a fixed rate. Each kept stamp carries an
:class:`~slamkit.datasets.Odometry` event (the true pose: clean odometry) and a
:class:`~slamkit.datasets.LaserScan` (:func:`~slamkit.sim.buildings.scans.
simulate_building_scans`); the truth is the pose at every stamp, the walls with the glass,
and their occupancy grid. Odometry errors are put on afterwards by
:func:`~slamkit.sim.odometry_errors.corrupt_odometry`, as :func:`build_building` (the
registry's ``building``) does with the typical :class:`OdometryErrorModel`.

Random streams: the plan comes from ``np.random.default_rng(seed)``; the drive, the laser
and the odometry errors from three independent streams spawned from the seed, so changing
a laser setting never changes the floor plan or the path.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from slamkit._validation import FloatArray
from slamkit.config import Section, config_from_mapping, config_to_dict, finite_above, setting
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.stream import (
    Dataset,
    Event,
    GroundTruth,
    LaserScan,
    LaserSpec,
    MotionSpec,
    Odometry,
)
from slamkit.errors import InputError
from slamkit.models import OdometryModel
from slamkit.sim.buildings.plan import Building, generate_building
from slamkit.sim.buildings.scans import simulate_building_scans
from slamkit.sim.odometry_errors import OdometryErrorModel, corrupt_odometry
from slamkit.sim.trajectory import follow_waypoints
from slamkit.sim.worlds import rasterize_segments

__all__ = [
    "CORPUS_SIZE",
    "BuildingConfig",
    "build_building",
    "build_building_dataset",
    "corpus_buildings",
    "drive_route",
    "gated_scan_indices",
]

CORPUS_SIZE = 20
"""How many buildings the generalisation corpus holds (seeds 0 to 19)."""

CONTROL_PERIOD = 0.2
"""[s] of the simulated control loop (the scans are gated from its poses)."""
CONTROL_NOISE = np.diag([0.03**2, math.radians(2.0) ** 2])
"""Execution noise of ``(v, ω)`` [m²/s², rad²/s²]: the true path wiggles about the plan."""
NOMINAL_ODOMETRY_COV = np.diag([math.radians(1.0) ** 2, 0.02**2, math.radians(1.0) ** 2])
"""The clean data set's ``(rot1, trans, rot2)`` covariance, as the CARMEN readers'."""


@dataclass(frozen=True)
class BuildingConfig(Section):
    """How a building is driven and scanned. Units: metres, seconds, degrees where named."""

    SECTION: ClassVar[str] = "scenario"

    speed: float = setting(0.5, finite_above(0.0), "a speed > 0 [m/s]")
    """Cruising speed [m/s] (slower in turns)."""
    scan_spacing: float = setting(0.3, finite_above(0.0), "a distance > 0 [m]")
    """A scan is kept after this much travel since the last one [m]."""
    scan_turn_deg: float = setting(10.0, finite_above(0.0), "an angle > 0 [deg]")
    """... or after this much turning [deg]."""
    n_beams: int = setting(181, lambda v: isinstance(v, int) and v >= 2, "an integer >= 2")
    """Beams over the 180° field of view (181: 1° apart)."""
    max_range: float = setting(30.0, finite_above(0.0), "a range > 0 [m]")
    """Beams meeting nothing within this read it [m]."""
    range_sigma: float = setting(0.01, finite_above(0.0), "a standard deviation > 0 [m]")
    """Range noise [m]."""
    grid_resolution: float = setting(0.05, finite_above(0.0), "a cell size > 0 [m]")
    """Cell size of the true occupancy grid [m]."""
    odometry_errors: bool = setting(True, lambda v: isinstance(v, bool), "true or false")
    """:func:`build_building` only: put the typical :class:`OdometryErrorModel` on the
    odometry (false: the clean odometry of :func:`build_building_dataset`)."""

    def laser_spec(self) -> LaserSpec:
        angles = np.linspace(-np.pi / 2.0, np.pi / 2.0, self.n_beams)
        return LaserSpec(angles, self.max_range, self.range_sigma)


def corpus_buildings(n: int = CORPUS_SIZE) -> list[int]:
    """The seeds of the corpus's buildings: ``building`` data sets ``0 .. n - 1``."""
    return list(range(n))


def gated_scan_indices(poses: FloatArray, spacing: float, turn: float) -> np.ndarray:
    """Indices of the poses ``(N, 3)`` at which a pose-gated logger keeps a scan: the first,
    every one after ``spacing`` metres of travel or ``turn`` radians of turning since the
    last kept one, and the last."""
    steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    turns = np.abs(np.angle(np.exp(1j * np.diff(poses[:, 2]))))
    keep = [0]
    dist = ang = 0.0
    for k in range(1, poses.shape[0]):
        dist += steps[k - 1]
        ang += turns[k - 1]
        if dist >= spacing or ang >= turn:
            keep.append(k)
            dist = ang = 0.0
    if keep[-1] != poses.shape[0] - 1:
        keep.append(poses.shape[0] - 1)
    return np.asarray(keep)


def drive_route(
    building: Building, config: BuildingConfig | None = None
) -> tuple[FloatArray, FloatArray]:
    """The stamps ``(N,)`` [s] and true poses ``(N, 3)`` at which a scan is kept on the drive
    along ``building``'s route (the drive's random stream is the first spawned from the
    building's seed)."""
    cfg = config or BuildingConfig()
    drive_rng = np.random.default_rng(building.seed).spawn(3)[0]
    drive = follow_waypoints(
        building.start, building.route, speed=cfg.speed, dt=CONTROL_PERIOD,
        control_cov=CONTROL_NOISE, rng=drive_rng, tolerance=0.3,
    )  # fmt: skip
    keep = gated_scan_indices(drive.poses, cfg.scan_spacing, math.radians(cfg.scan_turn_deg))
    return CONTROL_PERIOD * keep.astype(np.float64), drive.poses[keep]


def build_building_dataset(
    seed: int, config: BuildingConfig | None = None, *, building: Building | None = None
) -> Dataset:
    """The data set of building ``seed`` driven along its route, with clean odometry (see
    the module docstring); ``building`` saves regenerating a plan already at hand."""
    cfg = config or BuildingConfig()
    plan = building if building is not None else generate_building(seed)
    if plan.seed != seed:
        raise InputError(f"building: expected the plan of seed {seed}, got that of {plan.seed}")
    times, poses = drive_route(plan, cfg)
    laser_rng = np.random.default_rng(seed).spawn(3)[1]
    laser = cfg.laser_spec()
    ranges = simulate_building_scans(plan, poses, times, laser, laser_rng)
    events: list[Event] = []
    for k in range(times.size):
        events.append(Odometry(float(times[k]), poses[k].copy()))
        events.append(LaserScan(float(times[k]), ranges[k]))
    static = plan.static_map
    grid = rasterize_segments(static, cfg.grid_resolution, padding=0.5)
    return Dataset(
        name="building",
        events=tuple(events),
        motion=MotionSpec(OdometryModel(), NOMINAL_ODOMETRY_COV, source="odometry"),
        laser=laser,
        initial_pose=poses[0].copy(),
        initial_cov=np.diag([1e-4, 1e-4, math.radians(0.5) ** 2]),
        truth=GroundTruth(times=times, poses=poses, walls=static, occupancy=grid),
        description=plan.describe(),
        metadata={
            "kind": "simulated",
            "building_seed": int(seed),
            "odometry": "clean (the true poses)",
        },
        provenance=Provenance(options=config_to_dict(cfg)),
    )


def build_building(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """The registry's ``building``: the building ``seed`` chooses, driven, with the typical
    odometry errors put on (``odometry_errors = false`` for clean odometry; a
    :class:`BuildingConfig` in ``options``)."""
    cfg = config_from_mapping(BuildingConfig, options, "scenario")
    dataset = build_building_dataset(seed, cfg)
    if not cfg.odometry_errors:
        return dataset
    odometry_rng = np.random.default_rng(seed).spawn(3)[2]
    corrupted, _ = corrupt_odometry(dataset, OdometryErrorModel(), odometry_rng)
    return corrupted
