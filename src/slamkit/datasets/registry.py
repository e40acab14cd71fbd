"""The one list of every data set slamkit can load, simulated or real, by name.

To add a data set, write its builder or loader (a function
``(options, *, seed, data_root) -> Dataset`` reading ``options`` into a frozen dataclass)
and add one :class:`DatasetEntry` naming both to :data:`DATASETS` below. The CLI's
``slamkit data list`` and ``--data NAME`` read this table.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from slamkit.datasets.paths import find_data_root
from slamkit.datasets.stream import Dataset
from slamkit.errors import DataNotFoundError, UnknownNameError

__all__ = [
    "DATASETS",
    "FR079_MOUNTING",
    "DatasetEntry",
    "dataset_available",
    "get_dataset_entry",
    "list_datasets",
    "load_dataset",
    "registered_file",
]

Loader = Callable[..., Dataset]


@dataclass(frozen=True)
class DatasetEntry:
    """One registered data set. ``target`` is ``"module:function"``, imported on use so that
    listing the registry stays cheap; ``files`` are the paths a real data set needs under
    the data root."""

    name: str
    kind: Literal["simulated", "real"]
    description: str
    target: str
    files: tuple[str, ...] = ()
    defaults: Mapping[str, Any] = field(default_factory=dict)
    """Options preset for this entry (a scenario variant); the caller's options win."""
    options: str = ""
    """``"module:Class"`` of the frozen dataclass the loader reads its options into (the
    ``[dataset]`` table's keys; ``slamkit config show --data`` documents them from it);
    ``""``: the data set takes no options."""
    by_path: bool = False
    """A path to ``files[0]`` under the data root reads as this data set: with its
    :attr:`defaults`, and named in the data set's ``provenance.registered_as``
    (:func:`registered_file`), so ``--data …/aces.bag`` reads what ``--data aces-raw``
    reads (without what the other files add)."""

    def loader(self) -> Loader:
        module, _, func = self.target.partition(":")
        fn: Loader = getattr(importlib.import_module(module), func)
        return fn

    def options_type(self) -> type | None:
        """The class named by :attr:`options` (imported on use), None when there is none."""
        if not self.options:
            return None
        module, _, name = self.options.partition(":")
        cls: type = getattr(importlib.import_module(module), name)
        return cls


FR079_MOUNTING = (-0.04, 0.0, 0.0)
"""The laser's pose on the robot in the registered ``fr079-raw``: the original log's
``robot_frontlaser_offset`` (the frame of the benchmark's relations), not the bag's
``/tf_static`` (+0.04 m, the opposite sign)."""

# The Freiburg benchmark's raw logs (``*-raw``): a ROS 1 bag and its relations each, read by
# slamkit.datasets.rosbag with these defaults. The Intel logger stalls: 2033 scans lie in
# odometry gaps > 0.5 s, the longest 3.1 s (the scans stall with it); ACES has one scan in a
# 2.95 s gap: max_odom_gap 3.5 s. Freiburg 079: the bag's /tf_static puts the laser 4 cm
# ahead of base_link; the original CARMEN log says 4 cm behind (PARAM
# robot_frontlaser_offset -0.04), and the benchmark's relations are in that robot frame:
# graph SLAM's path scores 0.068 m read with +0.04 and 0.033 m with -0.04
# (docs/relations.md, "Which robot frame"). Its /odom poses never go backward, while the
# twist reverses on 514 of 8,950 steps (10.9 m): the poses were integrated from the
# unsigned speed, so they follow the twist's sign (docs/relations.md, "Freiburg 079's
# odometry backs up forward").
_GAPPY_LOGGER = {"max_odom_gap": 3.5}

DATASETS: dict[str, DatasetEntry] = {
    e.name: e
    for e in (
        DatasetEntry(
            "five-features",
            "simulated",
            "five point landmarks of the course notes, a loop, range-bearing readings",
            "slamkit.sim.scenarios:build_five_features",
            options="slamkit.sim.scenarios:LandmarkScenarioConfig",
        ),
        DatasetEntry(
            "five-features-range",
            "simulated",
            "the five-feature world, range-only readings in a 120° view (elongated ellipse)",
            "slamkit.sim.scenarios:build_five_features",
            options="slamkit.sim.scenarios:LandmarkScenarioConfig",
            defaults={"sensor": "range", "fov_deg": 120.0},
        ),
        DatasetEntry(
            "five-features-bearing",
            "simulated",
            "the five-feature world, bearing-only readings in a 120° view (no sense of depth)",
            "slamkit.sim.scenarios:build_five_features",
            options="slamkit.sim.scenarios:LandmarkScenarioConfig",
            defaults={"sensor": "bearing", "fov_deg": 120.0},
        ),
        DatasetEntry(
            "five-features-kidnapped",
            "simulated",
            "the five-feature world with a wrong prior: 3 m and 60 deg off (kidnapped start)",
            "slamkit.sim.scenarios:build_five_features",
            options="slamkit.sim.scenarios:LandmarkScenarioConfig",
            defaults={"prior_error_xy": (3.0, -2.0), "prior_error_theta_deg": 60.0},
        ),
        DatasetEntry(
            "landmark-loop",
            "simulated",
            "60 random landmarks along a 180 m loop that closes",
            "slamkit.sim.scenarios:build_landmark_loop",
            options="slamkit.sim.scenarios:LandmarkScenarioConfig",
        ),
        DatasetEntry(
            "landmark-clutter",
            "simulated",
            "150 landmarks 1.2 m apart, readings without ids (data association)",
            "slamkit.sim.scenarios:build_landmark_clutter",
            options="slamkit.sim.scenarios:LandmarkScenarioConfig",
        ),
        DatasetEntry(
            "landmark-loop-closure",
            "simulated",
            "100 landmarks along a 180 m loop driven round and on: first landmarks re-seen",
            "slamkit.sim.scenarios:build_landmark_loop_closure",
            options="slamkit.sim.scenarios:LandmarkScenarioConfig",
        ),
        DatasetEntry(
            "rooms-laser",
            "simulated",
            "laser tour of four rooms off a corridor, walls as ground truth",
            "slamkit.sim.scenarios:build_rooms_laser",
            options="slamkit.sim.scenarios:LaserScenarioConfig",
        ),
        DatasetEntry(
            "corridor-loop-laser",
            "simulated",
            "laser drive round a 30 m x 20 m ring of corridors and on past the start (loop "
            "closure), walls as ground truth",
            "slamkit.sim.loop_world:build_corridor_loop",
            options="slamkit.sim.scenarios:LaserScenarioConfig",
        ),
        DatasetEntry(
            "long-hallway-laser",
            "simulated",
            "laser drive down a bare 50 m hallway between two rooms and back (degenerate "
            "matching along it, loop closure on return), walls as ground truth",
            "slamkit.sim.loop_world:build_long_hallway",
            options="slamkit.sim.scenarios:LaserScenarioConfig",
        ),
        DatasetEntry(
            "building",
            "simulated",
            "a generated building chosen by --seed (corpus: seeds 0-19): corridors, offices, "
            "halls, clutter, glass, walking people; a 100-500 m route of loops; 181 beams, "
            "30 m; odometry with the typical OdometryErrorModel, glitches in metadata",
            "slamkit.sim.buildings:build_building",
            options="slamkit.sim.buildings.dataset:BuildingConfig",
        ),
        DatasetEntry(
            "rooms-laser-global",
            "simulated",
            "the laser tour of four rooms with no prior pose (global localization)",
            "slamkit.sim.scenarios:build_rooms_laser",
            options="slamkit.sim.scenarios:LaserScenarioConfig",
            defaults={"known_start": False},
        ),
        DatasetEntry(
            "rooms-laser-kidnapped",
            "simulated",
            "the laser tour of four rooms; at 30 s the robot is carried 40 s along its route",
            "slamkit.sim.scenarios:build_rooms_laser",
            options="slamkit.sim.scenarios:LaserScenarioConfig",
            defaults={"kidnap_time": 30.0, "kidnap_skip": 40.0},
        ),
        DatasetEntry(
            "mrclam-snapshots",
            "real",
            "UTIAS MRCLAM 1 cut into 9782 stationary range-bearing snapshots, 15 known "
            "landmarks, true poses",
            "slamkit.datasets.mrclam_snapshots:load_mrclam_snapshots",
            options="slamkit.datasets.mrclam_snapshots:MrclamSnapshotOptions",
            files=(
                "landmarks/utias_mrclam/triangulation_toolbox/mrclam1_groundtruth.csv",
                "landmarks/utias_mrclam/triangulation_toolbox/mrclam1_landmark.csv",
                "landmarks/utias_mrclam/triangulation_toolbox/mrclam1_measurement.csv",
            ),
        ),
        DatasetEntry(
            "mrclam1",
            "real",
            "UTIAS MRCLAM data set 1, robot 1: 100 Hz commanded velocities, range-bearing "
            "readings of 15 landmarks, Vicon landmark map; no prior, no true path",
            "slamkit.datasets.mrclam:load_mrclam",
            options="slamkit.datasets.mrclam:MrclamOptions",
            files=(
                "landmarks/utias_mrclam/MRCLAM_Dataset1/Barcodes.dat",
                "landmarks/utias_mrclam/MRCLAM_Dataset1/Landmark_Groundtruth.dat",
                "landmarks/utias_mrclam/MRCLAM_Dataset1/Robot1_Measurement.dat",
                "landmarks/utias_mrclam/MRCLAM_Dataset1/Robot1_Odometry.dat.gz",
            ),
        ),
        DatasetEntry(
            "plaza1",
            "real",
            "CMU Plaza 1: 5 Hz odometry increments, range-only readings of 4 radio beacons "
            "(ranges calibrated by 1/1.070), true path, known start",
            "slamkit.datasets.plaza:load_plaza1",
            options="slamkit.datasets.plaza:Plaza1Options",
            files=(
                "landmarks/plaza/Plaza1_DR.txt",
                "landmarks/plaza/Plaza1_TD.txt",
                "landmarks/plaza/Plaza1_GT.csv",
                "landmarks/plaza/Plaza1_TL.csv",
            ),
        ),
        DatasetEntry(
            "citytrees10000",
            "real",
            "iSAM cityTrees10000 (simulated): 10000 poses, 100 landmarks, 4443 robot-frame "
            "position readings, true poses",
            "slamkit.datasets.isam_landmarks:load_citytrees10000",
            options="slamkit.datasets.isam_landmarks:CityTreesOptions",
            files=("isam/cityTrees10000.txt", "isam/groundtruth/cityTrees10000_groundtruth.txt"),
        ),
        DatasetEntry(
            "victoria-park",
            "real",
            "Victoria Park truck: 40 Hz Ackermann odometry, laser range-bearing readings of "
            "299 trees (ids unknown), GPS positions as reference; start at the origin",
            "slamkit.datasets.victoria_park:load_victoria_park",
            options="slamkit.datasets.victoria_park:VictoriaParkOptions",
            files=(
                "landmarks/victoria_park/original_acfr/aa3_dr.csv.gz",
                "landmarks/victoria_park/original_acfr/aa3_gpsx.csv",
                "landmarks/victoria_park/slsjf/data_sensor_clean_clean.csv.gz",
            ),
        ),
        DatasetEntry(
            "victoria-park-laser",
            "real",
            "Victoria Park truck, raw laser: 7230 scans × 361 beams (0.5°, laser 3.78 m ahead "
            "of the rear axle), 40 Hz Ackermann speed/steering, GPS positions as reference",
            "slamkit.datasets.victoria_park_laser:load_victoria_park_laser",
            options="slamkit.datasets.victoria_park_laser:VictoriaParkLaserOptions",
            files=(
                "landmarks/victoria_park/raw_laser/laser.txt.gz",
                "landmarks/victoria_park/raw_laser/drs.txt.gz",
                "landmarks/victoria_park/raw_laser/gps.txt.gz",
                "landmarks/victoria_park/raw_laser/sensors_manager.txt.gz",
            ),
        ),
        DatasetEntry(
            "victoria-park-trees",
            "real",
            "Victoria Park truck: tree trunks slamkit extracts from the 7230 raw laser scans "
            "as range-bearing readings (ids unknown), 40 Hz Ackermann speed/steering, GPS",
            "slamkit.datasets.victoria_park_trees:load_victoria_park_trees",
            options="slamkit.datasets.victoria_park_trees:VictoriaParkTreesOptions",
            files=(
                "landmarks/victoria_park/raw_laser/laser.txt.gz",
                "landmarks/victoria_park/raw_laser/drs.txt.gz",
                "landmarks/victoria_park/raw_laser/gps.txt.gz",
                "landmarks/victoria_park/raw_laser/sensors_manager.txt.gz",
            ),
        ),
        DatasetEntry(
            "intel",
            "real",
            "Intel Research Lab, corrected CARMEN log: 910 scans × 180 beams, corrected poses "
            "as truth, odometry = truth + known noise",
            "slamkit.datasets.carmen:load_intel",
            options="slamkit.datasets.carmen:CarmenOptions",
            files=("laser/corrected_carmen/intel-corrected.log.gz",),
        ),
        DatasetEntry(
            "intel-mcl",
            "real",
            "Intel Research Lab in the 5 cm occupancy map slamkit builds from the corrected "
            "poses (known_grid); odometry = truth + known noise; no prior (global localization)",
            "slamkit.mapping.built_maps:load_intel_mcl",
            options="slamkit.mapping.built_maps:BuiltMapOptions",
            files=("laser/corrected_carmen/intel-corrected.log.gz",),
        ),
        DatasetEntry(
            "aces",
            "real",
            "ACES building, corrected CARMEN log: 440 scans × 180 beams (50 m clip), corrected "
            "poses as truth, odometry = truth + known noise",
            "slamkit.datasets.carmen:load_aces",
            options="slamkit.datasets.carmen:CarmenOptions",
            files=("laser/corrected_carmen/aces-corrected.log.gz",),
        ),
        DatasetEntry(
            "freiburg-079",
            "real",
            "Freiburg building 079, corrected CARMEN log: 4791 scans × 360 beams (0.5°), "
            "corrected poses as truth, odometry = truth + known noise",
            "slamkit.datasets.carmen:load_freiburg079",
            options="slamkit.datasets.carmen:CarmenOptions",
            files=("laser/corrected_carmen/freiburg-079-corrected.log.gz",),
        ),
        DatasetEntry(
            "intel-raw",
            "real",
            "Intel Research Lab, raw log (ROS 1 bag): 13,631 scans × 180 beams, raw wheel "
            "odometry at the scan stamps, 2984 reference relations as ground truth",
            "slamkit.datasets.rosbag:load_intel_raw",
            options="slamkit.datasets.rosbag:RosbagOptions",
            defaults=_GAPPY_LOGGER,
            by_path=True,
            files=("laser/rosbags/intel.bag", "laser/relations/intel.relations"),
        ),
        DatasetEntry(
            "aces-raw",
            "real",
            "ACES building, raw log (ROS 1 bag): 7374 scans × 180 beams (50 m), raw wheel "
            "odometry at the scan stamps, 1279 reference relations as ground truth",
            "slamkit.datasets.rosbag:load_aces_raw",
            options="slamkit.datasets.rosbag:RosbagOptions",
            defaults=_GAPPY_LOGGER,
            by_path=True,
            files=("laser/rosbags/aces.bag", "laser/relations/aces.relations"),
        ),
        DatasetEntry(
            "fr079-raw",
            "real",
            "Freiburg building 079, raw log (ROS 1 bag): 4934 scans × 360 beams (0.5°), laser "
            "4 cm behind the centre, raw wheel odometry at the scan stamps, 1685 reference "
            "relations",
            "slamkit.datasets.rosbag:load_fr079_raw",
            options="slamkit.datasets.rosbag:RosbagOptions",
            defaults={"mounting": FR079_MOUNTING, "odometry_direction": "twist"},
            by_path=True,
            files=("laser/rosbags/fr079.bag", "laser/relations/fr079.relations"),
        ),
        DatasetEntry(
            "loop5",
            "real",
            "DP-SLAM loop5: 551 scans × 181 beams with raw odometry, no ground truth",
            "slamkit.datasets.carmen:load_loop5",
            options="slamkit.datasets.carmen:DpSlamOptions",
            files=("laser/dpslam/loop5.log.gz",),
        ),
    )
}

DEFAULT_DATASET = "five-features"


def list_datasets() -> list[DatasetEntry]:
    return list(DATASETS.values())


def get_dataset_entry(name: str) -> DatasetEntry:
    try:
        return DATASETS[name]
    except KeyError:
        raise UnknownNameError("dataset", name, sorted(DATASETS)) from None


def dataset_available(entry: DatasetEntry, data_root: str | Path | None = None) -> bool:
    """Simulated sets are always available; real ones when all their files exist."""
    if entry.kind == "simulated":
        return True
    root = find_data_root(data_root)
    return root is not None and all((root / f).exists() for f in entry.files)


def load_dataset(
    name: str,
    *,
    seed: int = 0,
    options: Mapping[str, Any] | None = None,
    data_root: str | Path | None = None,
) -> Dataset:
    """Build or load the data set ``name``. ``options`` are the data set's own settings
    (a scenario's config); ``seed`` drives simulated ones; real ones are looked up under
    ``data_root`` (see :func:`slamkit.datasets.paths.data_root`)."""
    entry = get_dataset_entry(name)
    root = find_data_root(data_root)
    if entry.kind == "real" and not dataset_available(entry, data_root):
        missing = (
            entry.files if root is None else [f for f in entry.files if not (root / f).exists()]
        )
        where = (
            "under the data folder (set SLAMKIT_DATA)"
            if data_root is None
            else f"under the data folder {data_root} given"
            + (" (which is not a folder)" if not Path(data_root).is_dir() else "")
        )
        raise DataNotFoundError(f"data set {name!r} needs {', '.join(missing)} {where}")
    merged = {**entry.defaults, **dict(options or {})}
    dataset: Dataset = entry.loader()(merged, seed=seed, data_root=root)
    if dataset.name != entry.name:  # a variant carries its own registered name
        dataset = dataclasses.replace(dataset, name=entry.name)
    return dataset


def registered_file(path: Path, root: Path | None) -> DatasetEntry | None:
    """The entry (marked :attr:`~DatasetEntry.by_path`) whose first file under ``root`` is
    ``path``, or None."""
    if root is None:
        return None
    try:
        target = path.resolve()
    except OSError:
        return None
    for entry in DATASETS.values():
        if entry.by_path and entry.files:
            candidate = root / entry.files[0]
            if candidate.exists() and candidate.resolve() == target:
                return entry
    return None
