"""Data sets: the event-stream data model, the registry of named data sets, data paths.

Loaders for real data sets (one module per format) and simulated scenarios
(:mod:`slamkit.sim.scenarios`) all produce a :class:`Dataset`; each is registered once in
:data:`slamkit.datasets.registry.DATASETS`.
"""

from slamkit.datasets.paths import ENV_VAR, data_root, find_data_root
from slamkit.datasets.registry import (
    DATASETS,
    DEFAULT_DATASET,
    DatasetEntry,
    dataset_available,
    get_dataset_entry,
    list_datasets,
    load_dataset,
)
from slamkit.datasets.relations import Relations, read_relations
from slamkit.datasets.stream import (
    Control,
    Dataset,
    Event,
    GpsFix,
    GpsSpec,
    GroundTruth,
    KnownPose,
    LandmarkReadings,
    LandmarkSensorSpec,
    LaserScan,
    LaserSpec,
    MotionSpec,
    Odometry,
    group_by_time,
)

__all__ = [
    "DATASETS",
    "DEFAULT_DATASET",
    "ENV_VAR",
    "Control",
    "Dataset",
    "DatasetEntry",
    "Event",
    "GpsFix",
    "GpsSpec",
    "GroundTruth",
    "KnownPose",
    "LandmarkReadings",
    "LandmarkSensorSpec",
    "LaserScan",
    "LaserSpec",
    "MotionSpec",
    "Odometry",
    "Relations",
    "data_root",
    "dataset_available",
    "find_data_root",
    "get_dataset_entry",
    "group_by_time",
    "list_datasets",
    "load_dataset",
    "read_relations",
]
