"""The one list of every data set slamkit can load, simulated or real, by name.

To add a data set, write its builder or loader (a function
``(options, *, seed, data_root) -> Dataset``) and add one :class:`DatasetEntry` to
:data:`DATASETS` below. The CLI's ``slamkit data list`` and ``--data NAME`` read this table.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from slamkit.datasets.paths import find_data_root
from slamkit.datasets.stream import Dataset
from slamkit.errors import DataNotFoundError, UnknownNameError

__all__ = [
    "DATASETS",
    "DatasetEntry",
    "dataset_available",
    "get_dataset_entry",
    "list_datasets",
    "load_dataset",
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

    def loader(self) -> Loader:
        module, _, func = self.target.partition(":")
        fn: Loader = getattr(importlib.import_module(module), func)
        return fn


DATASETS: dict[str, DatasetEntry] = {
    e.name: e
    for e in (
        DatasetEntry(
            "five-features",
            "simulated",
            "five point landmarks of the course notes, a loop, range-bearing readings",
            "slamkit.sim.scenarios:build_five_features",
        ),
        DatasetEntry(
            "landmark-loop",
            "simulated",
            "60 random landmarks along a 180 m loop that closes",
            "slamkit.sim.scenarios:build_landmark_loop",
        ),
        DatasetEntry(
            "rooms-laser",
            "simulated",
            "laser tour of four rooms off a corridor, walls as ground truth",
            "slamkit.sim.scenarios:build_rooms_laser",
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
        raise DataNotFoundError(
            f"data set {name!r} needs {', '.join(missing)} under the data folder (set SLAMKIT_DATA)"
        )
    return entry.loader()(dict(options or {}), seed=seed, data_root=root)
