"""Lower layers never import higher ones: the order is the one ``docs/architecture.md``
draws, read from it here, so the picture and the code cannot drift apart.

The layers are the top-level packages of ``slamkit``, in the order of the diagram's lines
that start with a package name (``geometry/ prob/`` share a line and a floor); the modules
at the package's root (``errors``, ``_validation``, ``config``, ``runtime``) sit under all
of them. Every import counts, lazy and ``TYPE_CHECKING`` ones too
(:func:`test_import_cycles.import_graph`).

:data:`STILL_UP` lists the arrows up that remain: the estimators of ``slam/`` still use
building blocks that live in ``localization/`` and ``mapping/`` (issue 38 moves them down
a floor). The test fails on any arrow up that is not listed, and on a listed one that is
gone, so the list only shrinks.
"""

from __future__ import annotations

import re
from pathlib import Path

from test_import_cycles import import_graph

DOC = Path(__file__).resolve().parents[1] / "docs" / "architecture.md"

STILL_UP = {
    "slamkit.slam.ekf_slam -> slamkit.mapping.ekf_mapping",
    "slamkit.slam.ekf_slam.association -> slamkit.mapping.ekf_mapping",
    "slamkit.slam.ekf_slam.config -> slamkit.mapping.ekf_mapping",
    "slamkit.slam.ekf_slam.estimator -> slamkit.mapping.ekf_mapping",
    "slamkit.slam.fastslam.association -> slamkit.mapping.ekf_mapping",
    "slamkit.slam.fastslam.estimator -> slamkit.mapping.ekf_mapping",
    "slamkit.slam.fastslam.history -> slamkit.mapping.ekf_mapping",
    "slamkit.slam.grid_rbpf.estimator -> slamkit.mapping.grid",
    "slamkit.slam.grid_rbpf.estimator -> slamkit.mapping.inverse_model",
    "slamkit.slam.grid_rbpf.estimator -> slamkit.mapping.logodds",
    "slamkit.slam.grid_rbpf.maps -> slamkit.mapping.bresenham",
    "slamkit.slam.grid_rbpf.maps -> slamkit.mapping.grid",
    "slamkit.slam.grid_rbpf.maps -> slamkit.mapping.inverse_model",
    "slamkit.slam.grid_rbpf.maps -> slamkit.mapping.occupancy.rays",
    "slamkit.slam.laser_graph.estimator -> slamkit.mapping.inverse_model",
    "slamkit.slam.laser_graph.estimator -> slamkit.mapping.occupancy.config",
    "slamkit.slam.laser_graph.estimator -> slamkit.mapping.occupancy.mapper",
    "slamkit.slam.laser_graph.freespace -> slamkit.mapping.bresenham",
    "slamkit.slam.seif.association -> slamkit.mapping.ekf_mapping",
    "slamkit.slam.seif.config -> slamkit.mapping.ekf_mapping",
    "slamkit.slam.seif.estimator -> slamkit.mapping.ekf_mapping",
    "slamkit.slam.ukf_slam.config -> slamkit.localization.ukf",
    "slamkit.slam.ukf_slam.estimator -> slamkit.localization.ukf",
    "slamkit.slam.ukf_slam.kernels -> slamkit.localization.ukf",
}
"""Arrows up that remain (``importer -> imported``); see the module docstring."""


def layer_order() -> dict[str, int]:
    """Each top-level package's floor, 0 the highest (the diagram's order)."""
    text = DOC.read_text(encoding="utf-8")
    block = text.split("## Layers", 1)[1].split("```", 2)[1]
    floors: dict[str, int] = {}
    for line in block.splitlines():
        names = re.match(r"^ ((?:[a-z_]+/ ?)+)", line)
        if names:
            level = len(set(floors.values()))
            for name in names.group(1).split():
                floors[name.rstrip("/")] = level
    return floors


def arrows_up() -> set[str]:
    """Every import from a lower floor into a higher one, as ``importer -> imported``."""
    floors = layer_order()
    bottom = max(floors.values()) + 1

    def floor(module: str) -> int:  # the package's own __init__ (``slamkit``) sits on top
        parts = module.split(".")
        return -1 if len(parts) == 1 else floors.get(parts[1], bottom)

    found = set()
    for importer, imported in import_graph().items():
        for target in imported:
            if floor(target) < floor(importer):
                found.add(f"{importer} -> {target}")
    return found


def test_the_diagram_names_every_package_once() -> None:
    floors = layer_order()
    packages = {p.name for p in (DOC.parents[1] / "src" / "slamkit").iterdir() if p.is_dir()}
    packages.discard("__pycache__")
    assert packages <= set(floors), packages - set(floors)
    assert floors["cli"] == 0 and floors["geometry"] == floors["prob"]
    assert floors["slam"] < floors["estimation"] < floors["maps"]


def test_no_module_imports_a_higher_layer() -> None:
    found = arrows_up()
    assert found - STILL_UP == set(), "new arrows up"
    assert STILL_UP - found == set(), "gone: take them off STILL_UP"
