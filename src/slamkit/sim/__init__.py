"""Simulation: worlds, trajectories, sensors, named scenarios, generated buildings and the
odometry error model (rng injected)."""

from slamkit.sim.buildings import (
    Building,
    BuildingConfig,
    build_building_dataset,
    corpus_buildings,
    generate_building,
)
from slamkit.sim.mounted_laser import remount_laser
from slamkit.sim.odometry_errors import (
    OdometryErrorModel,
    OdometryGlitch,
    OdometryGlitches,
    corrupt_odometry,
)
from slamkit.sim.scans import ScanPair, corridor_world, random_scan_pairs, simulated_scan_pair
from slamkit.sim.scenarios import (
    LandmarkScenarioConfig,
    LaserScenarioConfig,
    build_five_features,
    build_landmark_loop,
    build_rooms_laser,
)
from slamkit.sim.sensors import observe_landmarks, observe_landmarks_labelled, simulate_scan
from slamkit.sim.trajectory import Drive, follow_waypoints, simulate_motion, waypoint_controls
from slamkit.sim.trunks import trunk_scan
from slamkit.sim.worlds import (
    five_feature_world,
    random_landmarks,
    rasterize_segments,
    rectangle_segments,
    rooms_world,
)

__all__ = [
    "Building",
    "BuildingConfig",
    "Drive",
    "LandmarkScenarioConfig",
    "LaserScenarioConfig",
    "OdometryErrorModel",
    "OdometryGlitch",
    "OdometryGlitches",
    "ScanPair",
    "build_building_dataset",
    "build_five_features",
    "build_landmark_loop",
    "build_rooms_laser",
    "corpus_buildings",
    "corridor_world",
    "corrupt_odometry",
    "five_feature_world",
    "follow_waypoints",
    "generate_building",
    "observe_landmarks",
    "observe_landmarks_labelled",
    "random_landmarks",
    "random_scan_pairs",
    "rasterize_segments",
    "rectangle_segments",
    "remount_laser",
    "rooms_world",
    "simulate_motion",
    "simulate_scan",
    "simulated_scan_pair",
    "trunk_scan",
    "waypoint_controls",
]
