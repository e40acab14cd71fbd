"""Named simulated scenarios. Each builder turns a config and a seed into a
:class:`~slamkit.datasets.Dataset` of exactly the form the real-data loaders produce, with
full ground truth. Same seed and config → identical data.

The builders are registered by name in :mod:`slamkit.datasets.registry` (the one list of
every data set), so ``slamkit run ESTIMATOR --data five-features`` just works.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.stream import (
    Control,
    Dataset,
    Event,
    GroundTruth,
    LandmarkReadings,
    LandmarkSensorSpec,
    LaserScan,
    LaserSpec,
    MotionSpec,
)
from slamkit.errors import ConfigError, InputError
from slamkit.maps import LandmarkMap, SegmentMap
from slamkit.models import UnicycleEuler
from slamkit.sim.sensors import observe_landmarks_labelled, simulate_scan
from slamkit.sim.trajectory import follow_waypoints
from slamkit.sim.worlds import (
    five_feature_world,
    random_landmarks,
    rasterize_segments,
    rooms_world,
)

__all__ = [
    "LandmarkScenarioConfig",
    "LaserScenarioConfig",
    "build_five_features",
    "build_landmark_clutter",
    "build_landmark_loop",
    "build_landmark_loop_closure",
    "build_rooms_laser",
    "landmark_dataset",
]


@dataclass(frozen=True)
class LandmarkScenarioConfig:
    """A unicycle robot observing point landmarks. Units: metres, seconds, degrees where the
    name says so."""

    dt: float = 0.1
    """Control period [s]."""
    speed: float = 1.0
    """Commanded forward speed [m/s]."""
    laps: int = 1
    """How many times the route is driven."""
    max_steps: int = 2_000_000
    """Refuse a drive estimated to take more control steps than this (a typo such as
    ``laps = 100000000`` or ``dt = 1e-7`` would otherwise run for hours or run out of
    memory)."""
    sigma_v: float = 0.10
    """Standard deviation of the executed speed about the commanded one [m/s]."""
    sigma_omega_deg: float = 5.0
    """Standard deviation of the executed turn rate [deg/s]."""
    sensor: Literal["range-bearing", "range", "bearing"] = "range-bearing"
    sigma_range: float = 0.10
    """Range noise [m]."""
    sigma_bearing_deg: float = 2.0
    """Bearing noise [deg]."""
    max_range: float = 8.0
    """Landmarks farther than this are not seen [m]."""
    min_range: float = 0.3
    """Landmarks closer than this are not seen [m] (the robot may drive right past one)."""
    fov_deg: float = 360.0
    """Field of view centred on the heading [deg]."""
    identities: bool = True
    """Whether readings carry the landmark's id (False: data association is the estimator's job)."""
    observe_every: int = 1
    """Readings every this many control steps."""
    initial_sigma_xy: float = 0.05
    """Prior standard deviation of the start position [m]; the true start is drawn from it."""
    initial_sigma_theta_deg: float = 1.0
    """Prior standard deviation of the start heading [deg]."""
    known_start: bool = True
    """False: the data set carries no prior pose (global localization)."""
    prior_error_xy: tuple[float, float] = (0.0, 0.0)
    """Added to the prior mean given to estimators [m]: a wrong prior (kidnapped robot)."""
    prior_error_theta_deg: float = 0.0
    """Added to the prior heading given to estimators [deg]."""
    kidnap_time: float = -1.0
    """If >= 0: at this time [s] the robot is carried to where the route is ``kidnap_skip``
    seconds later, without any control telling so (the kidnapped-robot problem)."""
    kidnap_skip: float = 10.0
    """How far along the route [s] the kidnapper carries the robot."""

    def __post_init__(self) -> None:
        _check_kidnap(self.kidnap_time, self.kidnap_skip)
        _check_finite(self, (
            "dt", "speed", "sigma_v", "sigma_omega_deg", "sigma_range", "sigma_bearing_deg",
            "initial_sigma_xy", "initial_sigma_theta_deg", "prior_error_theta_deg",
            "kidnap_time", "kidnap_skip", "fov_deg", "min_range",
        ))  # fmt: skip
        for name in ("dt", "speed", "max_range", "fov_deg"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive number, got {getattr(self, name)}")
        for name in ("sigma_v", "sigma_omega_deg", "initial_sigma_xy", "initial_sigma_theta_deg"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{name}: expected a number >= 0, got {getattr(self, name)}")
        if not (self.sigma_range > 0 and self.sigma_bearing_deg > 0):
            raise ConfigError("sigma_range and sigma_bearing_deg: expected positive numbers")
        if not 0.0 <= self.min_range < self.max_range:
            raise ConfigError(
                f"min_range: expected 0 <= min_range < max_range ({self.max_range}), "
                f"got {self.min_range}"
            )
        if self.laps < 1 or self.observe_every < 1:
            raise ConfigError("laps and observe_every: expected integers >= 1")

    def control_cov(self) -> np.ndarray:
        return np.diag([self.sigma_v**2, np.deg2rad(self.sigma_omega_deg) ** 2])

    def sensor_spec(self) -> LandmarkSensorSpec:
        sr, sb = self.sigma_range, np.deg2rad(self.sigma_bearing_deg)
        cov = {"range-bearing": np.diag([sr**2, sb**2]), "range": [[sr**2]], "bearing": [[sb**2]]}
        return LandmarkSensorSpec(
            kind=self.sensor,
            noise_cov=np.asarray(cov[self.sensor], dtype=float),
            max_range=self.max_range,
            min_range=self.min_range,
            fov=np.deg2rad(min(self.fov_deg, 360.0)),
            identities=self.identities,
        )

    def initial_cov(self) -> np.ndarray:
        s, st = self.initial_sigma_xy, np.deg2rad(self.initial_sigma_theta_deg)
        return np.diag([s**2, s**2, st**2])


@dataclass(frozen=True)
class LaserScenarioConfig:
    """A unicycle robot with a 2D laser scanner in a building of walls."""

    dt: float = 0.2
    speed: float = 0.8
    laps: int = 1
    max_steps: int = 2_000_000
    """As in :class:`LandmarkScenarioConfig`."""
    sigma_v: float = 0.05
    sigma_omega_deg: float = 3.0
    n_beams: int = 181
    fov_deg: float = 180.0
    max_range: float = 12.0
    sigma_range: float = 0.03
    """Per-beam range noise [m]."""
    grid_resolution: float = 0.05
    """Resolution of the rasterised true occupancy map [m]."""
    initial_sigma_xy: float = 0.05
    initial_sigma_theta_deg: float = 1.0
    known_start: bool = True
    """False: no prior pose (global localization from a uniform start)."""
    kidnap_time: float = -1.0
    """If >= 0: at this time [s] the robot is carried ``kidnap_skip`` seconds along its route."""
    kidnap_skip: float = 40.0

    def __post_init__(self) -> None:
        _check_kidnap(self.kidnap_time, self.kidnap_skip)
        _check_finite(self, (
            "dt", "speed", "sigma_v", "sigma_omega_deg", "fov_deg", "max_range", "sigma_range",
            "grid_resolution", "initial_sigma_xy", "initial_sigma_theta_deg", "kidnap_time",
            "kidnap_skip",
        ))  # fmt: skip
        for name in ("sigma_v", "sigma_omega_deg", "initial_sigma_xy", "initial_sigma_theta_deg"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{name}: expected a number >= 0, got {getattr(self, name)}")
        if self.n_beams < 1:
            raise ConfigError(f"n_beams: expected >= 1, got {self.n_beams}")
        for name in ("dt", "speed", "fov_deg", "max_range", "sigma_range", "grid_resolution"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive number, got {getattr(self, name)}")

    def laser_spec(self) -> LaserSpec:
        half = np.deg2rad(min(self.fov_deg, 360.0)) / 2.0
        endpoint = self.fov_deg < 360.0
        angles = np.linspace(-half, half, self.n_beams, endpoint=endpoint)
        return LaserSpec(angles, self.max_range, self.sigma_range)


def _check_finite(config: object, names: tuple[str, ...]) -> None:
    """Noise levels, periods and speeds must be finite: ``inf`` passes a ``>= 0`` test but
    hangs the sampler (a covariance of inf) or never ends a drive."""
    for name in names:
        value = getattr(config, name)
        if not math.isfinite(value):
            raise ConfigError(f"{name}: expected a finite number, got {value}")


def _check_kidnap(kidnap_time: float, kidnap_skip: float) -> None:
    if kidnap_time >= 0 and not kidnap_skip > 0:
        raise ConfigError(f"kidnap_skip: expected a positive duration, got {kidnap_skip}")


def _kidnap_steps(kidnap_time: float, skip: float, dt: float) -> tuple[int, int] | None:
    """``(step, skipped steps)`` of a kidnapping, or None (``kidnap_time < 0``)."""
    if kidnap_time < 0:
        return None
    return round(kidnap_time / dt), round(skip / dt)


def _follow(
    start: np.ndarray,
    waypoints: np.ndarray,
    *,
    speed: float,
    dt: float,
    laps: int,
    control_cov: np.ndarray,
    rng: np.random.Generator,
    kidnap_time: float,
    kidnap_skip: float,
    max_steps: int,
    tolerance: float = 0.3,
) -> tuple[np.ndarray, np.ndarray]:
    """True poses and commanded controls of a closed-loop drive along the waypoints;
    refuses a drive of more than ``max_steps`` steps (estimated from the route's length,
    the laps, the speed and the period) before allocating it."""
    route = float(np.sum(np.hypot(*np.diff(np.vstack([waypoints, waypoints[:1]]), axis=0).T)))
    steps = laps * route / (speed * dt)
    if steps > max_steps:
        raise ConfigError(
            f"laps = {laps}, speed = {speed} m/s, dt = {dt} s: about {steps:.3g} steps of a "
            f"{route:.0f}-m route, above the limit of {max_steps:,} (set max_steps to allow it)"
        )
    try:
        drive = follow_waypoints(
            start, waypoints, speed=speed, dt=dt, laps=laps, tolerance=tolerance,
            control_cov=control_cov, rng=rng,
            kidnap=_kidnap_steps(kidnap_time, kidnap_skip, dt),
        )  # fmt: skip
    except InputError as exc:
        if "kidnap" in str(exc):
            raise ConfigError(
                f"kidnap_time + kidnap_skip = {kidnap_time + kidnap_skip} s lies beyond the route"
            ) from None
        raise
    return drive.poses, drive.controls


def _start(
    pose: np.ndarray, cov: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """The prior mean and the true start drawn from N(prior mean, cov)."""
    # multivariate_normal factors by SVD, so a zero (known) start covariance is fine.
    return pose, rng.multivariate_normal(pose, cov)


def landmark_dataset(
    name: str,
    description: str,
    cfg: LandmarkScenarioConfig,
    world: LandmarkMap,
    start_pose: np.ndarray,
    waypoints: np.ndarray,
    rng: np.random.Generator,
) -> Dataset:
    """A landmark scenario over a given ``world``: the robot drives from ``start_pose`` through
    ``waypoints (W, 2)`` under ``cfg`` (speed, noise, sensor, laps), reading the landmarks on
    the way; the data set carries the truth and the true association of every reading."""
    prior, x0 = _start(start_pose, cfg.initial_cov(), rng)
    model = UnicycleEuler()
    truth, controls = _follow(
        x0, waypoints, speed=cfg.speed, dt=cfg.dt, laps=cfg.laps, control_cov=cfg.control_cov(),
        rng=rng, kidnap_time=cfg.kidnap_time, kidnap_skip=cfg.kidnap_skip,
        max_steps=cfg.max_steps,
    )  # fmt: skip
    times = cfg.dt * np.arange(truth.shape[0], dtype=np.float64)
    prior = prior + np.array([*cfg.prior_error_xy, np.deg2rad(cfg.prior_error_theta_deg)])
    sensor = cfg.sensor_spec()
    events: list[Event] = []
    reading_ids: list[np.ndarray] = []  # the true association, for scoring an estimator
    for k in range(truth.shape[0]):
        if k > 0:
            events.append(Control(float(times[k]), controls[k - 1], cfg.dt))
        if k % cfg.observe_every == 0:
            z, ids, true_ids = observe_landmarks_labelled(truth[k], world, sensor, rng)
            if ids.size:
                events.append(LandmarkReadings(float(times[k]), z, ids))
                reading_ids.append(true_ids)
    return Dataset(
        name=name,
        events=tuple(events),
        motion=MotionSpec(model, cfg.control_cov()),
        landmark_sensor=sensor,
        initial_pose=prior if cfg.known_start else None,
        initial_cov=cfg.initial_cov() if cfg.known_start else None,
        known_landmarks=world,
        truth=GroundTruth(
            times=times, poses=truth, landmarks=world, reading_ids=tuple(reading_ids)
        ),
        description=description,
        metadata={"kind": "simulated"},
        provenance=Provenance(options=config_to_dict(cfg)),
    )


def build_five_features(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """The five-feature world of the course notes: a loop around five landmarks."""
    cfg = config_from_mapping(LandmarkScenarioConfig, options, "scenario")
    rng = np.random.default_rng(seed)
    waypoints = np.array([[8.0, 0.0], [10.0, 5.0], [7.0, 9.0], [2.0, 9.0], [0.0, 4.0], [0.0, 0.0]])
    return landmark_dataset(
        "five-features",
        "five point landmarks, a ~35 m loop, range-bearing readings",
        cfg,
        five_feature_world(),
        np.array([0.0, 0.0, 0.0]),
        waypoints,
        rng,
    )


def build_landmark_loop(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """A long rectangular loop (60 m × 30 m) past 60 random landmarks: the robot returns to
    its start, so SLAM estimators see a loop closure."""
    defaults = {"max_range": 6.0, "speed": 1.5}
    cfg = config_from_mapping(LandmarkScenarioConfig, {**defaults, **options}, "scenario")
    rng = np.random.default_rng(seed)
    world = random_landmarks(rng, 60, (-5.0, -5.0, 65.0, 35.0), min_separation=2.5)
    waypoints = np.array([[60.0, 0.0], [60.0, 30.0], [0.0, 30.0], [0.0, 0.0]])
    return landmark_dataset(
        "landmark-loop",
        "60 random landmarks along a 180 m rectangular loop that closes",
        cfg,
        world,
        np.array([0.0, 0.0, 0.0]),
        waypoints,
        rng,
    )


def build_landmark_clutter(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """A cluttered field for data-association tests: 150 random landmarks at least 1.2 m
    apart in a 30 m × 30 m square (about 13 in view, 6 m range), an 80 m square route that
    closes, and readings WITHOUT identities (ids ``-1``, shuffled) at 2 Hz. Pass
    ``identities=True`` for the same world with labels (to score an association)."""
    defaults = {"identities": False, "max_range": 6.0, "observe_every": 5}
    cfg = config_from_mapping(LandmarkScenarioConfig, {**defaults, **options}, "scenario")
    rng = np.random.default_rng(seed)
    world = random_landmarks(rng, 150, (-5.0, -5.0, 25.0, 25.0), min_separation=1.2)
    waypoints = np.array([[20.0, 0.0], [20.0, 20.0], [0.0, 20.0], [0.0, 0.0]])
    return landmark_dataset(
        "landmark-clutter",
        "150 landmarks 1.2 m apart around an 80 m square route, readings without ids",
        cfg,
        world,
        np.array([0.0, 0.0, 0.0]),
        waypoints,
        rng,
    )


def build_landmark_loop_closure(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """Loop closure: 100 landmarks (2.5 m apart) only in a 10 m wide band along a
    60 m × 30 m rectangular route, so each is seen from one stretch of road; the robot
    drives round once and 20 m on, re-observing its first landmarks after ~115 s."""
    defaults = {"max_range": 6.0, "speed": 1.5}
    cfg = config_from_mapping(LandmarkScenarioConfig, {**defaults, **options}, "scenario")
    rng = np.random.default_rng(seed)
    bands = [(-5.0, -5.0, 65.0, 5.0), (55.0, 5.0, 65.0, 25.0), (-5.0, 25.0, 65.0, 35.0),
             (-5.0, 5.0, 5.0, 25.0)]  # fmt: skip
    parts = [random_landmarks(rng, n, b, min_separation=2.5).positions
             for n, b in zip((33, 17, 33, 17), bands, strict=True)]  # fmt: skip
    waypoints = np.array([[60.0, 0.0], [60.0, 30.0], [0.0, 30.0], [0.0, 0.0], [20.0, 0.0]])
    return landmark_dataset(
        "landmark-loop-closure",
        "100 landmarks along a 180 m rectangular loop, driven round and 20 m on",
        cfg,
        LandmarkMap.from_positions(np.concatenate(parts)),
        np.array([0.0, 0.0, 0.0]),
        waypoints,
        rng,
    )


def build_rooms_laser(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """A laser robot touring four rooms off a corridor (walls as segments; the true
    occupancy grid is the walls rasterised)."""
    cfg = config_from_mapping(LaserScenarioConfig, options, "scenario")
    rng = np.random.default_rng(seed)
    walls: SegmentMap = rooms_world()
    waypoints = np.array(
        [
            [4.0, 6.0], [4.0, 3.0], [7.0, 2.5], [4.0, 4.0], [4.0, 6.0], [14.0, 6.0],
            [14.0, 2.5], [18.0, 2.0], [17.8, 4.2], [14.0, 4.0], [16.0, 6.0], [16.0, 9.5],
            [18.0, 10.5], [16.0, 8.0], [16.0, 6.0], [6.0, 6.0], [6.0, 9.0], [4.0, 10.5],
            [6.0, 8.0], [6.0, 6.0],
        ]
    )  # fmt: skip
    start = np.array([1.5, 6.0, 0.0])

    s, st = cfg.initial_sigma_xy, np.deg2rad(cfg.initial_sigma_theta_deg)
    init_cov = np.diag([s**2, s**2, st**2])
    prior, x0 = _start(start, init_cov, rng)
    model = UnicycleEuler()
    q = np.diag([cfg.sigma_v**2, np.deg2rad(cfg.sigma_omega_deg) ** 2])
    truth, controls = _follow(
        x0, waypoints, speed=cfg.speed, dt=cfg.dt, laps=cfg.laps, control_cov=q, rng=rng,
        kidnap_time=cfg.kidnap_time, kidnap_skip=cfg.kidnap_skip, tolerance=0.25,
        max_steps=cfg.max_steps,
    )  # fmt: skip
    times = cfg.dt * np.arange(truth.shape[0], dtype=np.float64)
    laser = cfg.laser_spec()
    events: list[Event] = []
    for k in range(truth.shape[0]):
        if k > 0:
            events.append(Control(float(times[k]), controls[k - 1], cfg.dt))
        events.append(LaserScan(float(times[k]), simulate_scan(truth[k], walls, laser, rng)))
    grid = rasterize_segments(walls, cfg.grid_resolution, padding=0.5)
    return Dataset(
        name="rooms-laser",
        events=tuple(events),
        motion=MotionSpec(model, q),
        laser=laser,
        initial_pose=prior if cfg.known_start else None,
        initial_cov=init_cov if cfg.known_start else None,
        known_grid=grid,
        truth=GroundTruth(times=times, poses=truth, walls=walls, occupancy=grid),
        description="laser tour of four rooms off a corridor (20 m × 12 m)",
        metadata={"kind": "simulated"},
        provenance=Provenance(options=config_to_dict(cfg)),
    )
