"""Generated buildings for a generalisation corpus: random floor plans chosen by a seed
(corridors, offices with doors, open halls, clutter, glass, walking people) and a route of
loops through them, driven and scanned into a :class:`~slamkit.datasets.Dataset` with the
truth. See ``docs/simulation.md``."""

from slamkit.sim.buildings.dataset import (
    CORPUS_SIZE,
    BuildingConfig,
    build_building,
    build_building_dataset,
    corpus_buildings,
    drive_route,
    gated_scan_indices,
)
from slamkit.sim.buildings.plan import Building, Walkers, generate_building
from slamkit.sim.buildings.scans import simulate_building_scans

__all__ = [
    "CORPUS_SIZE",
    "Building",
    "BuildingConfig",
    "Walkers",
    "build_building",
    "build_building_dataset",
    "corpus_buildings",
    "drive_route",
    "gated_scan_indices",
    "generate_building",
    "simulate_building_scans",
]
