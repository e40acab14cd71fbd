"""Simulation: worlds, trajectories, sensors and named scenarios (rng injected)."""

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
from slamkit.sim.worlds import (
    five_feature_world,
    random_landmarks,
    rasterize_segments,
    rectangle_segments,
    rooms_world,
)

__all__ = [
    "Drive",
    "LandmarkScenarioConfig",
    "LaserScenarioConfig",
    "ScanPair",
    "build_five_features",
    "build_landmark_loop",
    "build_rooms_laser",
    "corridor_world",
    "five_feature_world",
    "follow_waypoints",
    "observe_landmarks",
    "observe_landmarks_labelled",
    "random_landmarks",
    "random_scan_pairs",
    "rasterize_segments",
    "rectangle_segments",
    "rooms_world",
    "simulate_motion",
    "simulate_scan",
    "simulated_scan_pair",
    "waypoint_controls",
]
