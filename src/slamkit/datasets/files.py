"""Data sets from a path: a user's own laser log, read by the reader its name calls for.

:func:`load_file` picks the reader from the path:

* ``*.bag``: a ROS 1 bag; a folder holding ``metadata.yaml``: a ROS 2 bag; ``*.db3`` or
  ``*.mcap``: one ROS 2 storage file — all read by :func:`slamkit.datasets.rosbag.read_rosbag`;
* ``*.clf``, ``*.log`` and gzipped ones (``*.gz``: ``.log.gz``, ``.clf.gz``, gzip recognised
  by the content): a laser log of the CARMEN family, its reader chosen by the content
  (:func:`laser_log_format`): a *corrected* CARMEN log (its scans' poses are a SLAM result;
  ``NEFF`` lines, or "corrected" in the name) by
  :func:`slamkit.datasets.carmen.read_carmen_log`, which keeps the poses as the truth and
  makes odometry from them with known noise (seeded); a DP-SLAM log (``Odometry``/``Laser``
  lines) by :func:`slamkit.datasets.carmen.read_dpslam_log`; any other by
  :func:`slamkit.datasets.carmen_raw.read_carmen_raw_log`, with the robot's raw odometry;
* ``*.csv``: landmark data (controls or odometry, readings, optional truth), read by
  :func:`slamkit.datasets.landmark_csv.read_landmark_csv`.

``options`` are the reader's options (:class:`~slamkit.datasets.rosbag.RosbagOptions`,
:class:`~slamkit.datasets.carmen_raw.CarmenRawOptions`, …), from a config file's
``[dataset]`` table; the key ``reader`` (one of :data:`READERS`) overrides the choice.
:func:`load_data` is what ``slamkit run --data`` calls: a registered name loads that data
set, anything else is taken as a path. A path that is one of the registered raw bags
under the data folder is read with that data set's default options (the registered name is
``provenance.registered_as``), so ``--data …/aces.bag`` reads what ``--data aces-raw``
reads, without its relations. ``provenance.path`` holds the absolute path read and
``provenance.reader`` the reader (:class:`~slamkit.datasets.provenance.Provenance`).
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

from slamkit.datasets.paths import find_data_root
from slamkit.datasets.registry import DATASETS, load_dataset, registered_file
from slamkit.datasets.stream import Dataset
from slamkit.datasets.text import head_lines
from slamkit.errors import ConfigError, DataNotFoundError, DatasetFormatError, UnknownNameError

__all__ = [
    "READERS",
    "READER_OPTIONS",
    "SUPPORTED_FORMATS",
    "data_label",
    "dataset_options_type",
    "file_format",
    "file_options",
    "laser_log_format",
    "load_data",
    "load_file",
    "reader_for",
    "reader_options_type",
]

SUPPORTED_FORMATS = (
    "ROS 1 .bag, ROS 2 bag folder (with metadata.yaml), ROS 2 .db3 or .mcap file, "
    "CARMEN .clf/.log (or gzipped: .clf.gz, .log.gz, .gz), landmark data .csv"
)
"""The formats :func:`load_file` reads, for messages."""

_ROS_SUFFIXES = (".bag", ".db3", ".mcap")
_CARMEN_SUFFIXES = (".clf", ".log", ".gz")
_CSV_SUFFIXES = (".csv",)
_LABEL_SUFFIXES = (".gz", ".bag", ".db3", ".mcap", ".clf", ".log", ".csv")

FileFormat = Literal["rosbag", "carmen-raw", "carmen-corrected", "dpslam", "landmark-csv"]
READERS: tuple[FileFormat, ...] = (
    "rosbag",
    "carmen-raw",
    "carmen-corrected",
    "dpslam",
    "landmark-csv",
)
"""The readers a path can go to; the ``reader`` option names one to bypass the choice."""

READER_OPTIONS: dict[FileFormat, str] = {
    "rosbag": "slamkit.datasets.rosbag:RosbagOptions",
    "carmen-raw": "slamkit.datasets.carmen_raw:CarmenRawOptions",
    "carmen-corrected": "slamkit.datasets.carmen:CarmenOptions",
    "dpslam": "slamkit.datasets.carmen:DpSlamOptions",
    "landmark-csv": "slamkit.datasets.landmark_csv:LandmarkCsvOptions",
}
"""``"module:Class"`` of each reader's options (the ``[dataset]`` keys besides ``reader``)."""

SNIFF_LINES = 2000
"""Lines of a CARMEN-family log read to tell its kind (a corrected log's first ``NEFF``
follows its first scan)."""


def laser_log_format(path: Path) -> FileFormat:
    """Which reader reads a log of the CARMEN family: ``"dpslam"`` when its first message
    is ``Odometry`` or ``Laser``; ``"carmen-corrected"`` when it has ``NEFF`` lines (the
    effective sample size the correcting filter wrote beside each scan) or its name says
    "corrected"; else ``"carmen-raw"``."""
    if "corrected" in path.name.lower():
        return "carmen-corrected"
    kinds = [line.split(None, 1)[0] for line in head_lines(path, SNIFF_LINES) if line.strip()]
    kinds = [k for k in kinds if not k.startswith("#")]
    if kinds and kinds[0] in ("Odometry", "Laser"):
        return "dpslam"
    if "NEFF" in kinds:
        return "carmen-corrected"
    return "carmen-raw"


def file_format(path: str | Path) -> FileFormat:
    """Which reader reads ``path`` (see the module docstring); a missing path raises
    :class:`~slamkit.errors.DataNotFoundError`, an unknown kind of file
    :class:`~slamkit.errors.DatasetFormatError`, each in one line listing the formats."""
    p = Path(path)
    if not p.exists():
        raise DataNotFoundError(f"{p}: not found (supported: {SUPPORTED_FORMATS})")
    if p.is_dir():
        if (p / "metadata.yaml").exists():
            return "rosbag"
        raise DatasetFormatError(
            f"a folder without metadata.yaml is not a ROS 2 bag (supported: {SUPPORTED_FORMATS})",
            p,
        )
    suffix = p.suffix.lower()
    if suffix in _ROS_SUFFIXES:
        return "rosbag"
    if suffix in _CARMEN_SUFFIXES:
        return laser_log_format(p)
    if suffix in _CSV_SUFFIXES:
        return "landmark-csv"
    raise DatasetFormatError(
        f"unknown kind of file {suffix or '(no suffix)'!r} (supported: {SUPPORTED_FORMATS})", p
    )


def reader_for(path: str | Path, options: Mapping[str, Any] | None = None) -> FileFormat:
    """The reader :func:`load_file` reads ``path`` with: ``options["reader"]`` when given
    (checked), else the one its kind calls for (:func:`file_format`)."""
    named = _reader_option((options or {}).get("reader"))
    return named if named is not None else file_format(Path(path).expanduser())


def reader_options_type(reader: str) -> type:
    """The options class of ``reader`` (one of :data:`READERS`): the keys its ``[dataset]``
    table takes besides ``reader``."""
    kind = _reader_option(reader)
    assert kind is not None  # a string: a reader's name, or ConfigError above
    module, _, name = READER_OPTIONS[kind].partition(":")
    cls: type = getattr(importlib.import_module(module), name)
    return cls


def dataset_options_type(spec: str, options: Mapping[str, Any] | None = None) -> type | None:
    """The class a data set reads its ``[dataset]`` options into: a registered name's
    (:meth:`~slamkit.datasets.registry.DatasetEntry.options_type`; None when it takes
    none), else that of the reader of the path ``spec`` (:func:`reader_for`; a missing path
    raises :class:`~slamkit.errors.DataNotFoundError`)."""
    if spec in DATASETS:
        return DATASETS[spec].options_type()
    return reader_options_type(reader_for(spec, options))


def load_file(
    path: str | Path,
    options: Mapping[str, Any] | None = None,
    *,
    name: str | None = None,
    seed: int = 0,
) -> Dataset:
    """Read the log at ``path`` with the reader its kind calls for (see the module
    docstring); ``options`` go to that reader (unknown keys: ConfigError), except
    ``reader``, which names the reader; ``seed`` draws the noise of a corrected log's
    odometry."""
    p = Path(path).expanduser()
    opts = dict(options or {})
    kind = _reader_option(opts.pop("reader", None)) or file_format(p)
    if not p.exists():
        raise DataNotFoundError(f"{p}: not found (supported: {SUPPORTED_FORMATS})")
    if kind == "rosbag":
        from slamkit.datasets.rosbag import read_rosbag

        dataset = read_rosbag(p, opts, name=name)
    elif kind == "landmark-csv":
        from slamkit.datasets.landmark_csv import read_landmark_csv

        dataset = read_landmark_csv(p, opts, name=name)
    elif kind == "carmen-corrected":
        from slamkit.datasets.carmen import read_carmen_log

        dataset = read_carmen_log(p, opts, seed=seed, name=name)
    elif kind == "dpslam":
        from slamkit.datasets.carmen import read_dpslam_log

        dataset = read_dpslam_log(p, opts, name=name)
    else:
        from slamkit.datasets.carmen_raw import read_carmen_raw_log

        dataset = read_carmen_raw_log(p, opts, name=name)
    return dataset.with_provenance(dataset.provenance.read_from(str(p.resolve()), kind))


def _reader_option(value: Any) -> FileFormat | None:
    if value is None:
        return None
    for reader in READERS:
        if value == reader:
            return reader
    raise ConfigError(f"reader: expected one of {', '.join(READERS)}, got {value!r}")


def file_options(
    path: str | Path,
    options: Mapping[str, Any] | None = None,
    *,
    data_root: str | Path | None = None,
) -> tuple[FileFormat, Any, str | None]:
    """How :func:`load_data` would read the file at ``path``, without reading it: the reader
    (:func:`reader_for`), its options object built from ``options`` (over a registered
    bag's defaults; unknown keys or bad values: :class:`~slamkit.errors.ConfigError`), and
    the registered name of the file (None when it is not one of the registered bags)."""
    from slamkit.config import config_from_mapping

    p = _as_path(str(path))
    merged, registered = _registered_options(p, options, data_root)
    reader = reader_for(p, merged)
    merged.pop("reader", None)
    return reader, config_from_mapping(reader_options_type(reader), merged, "dataset"), registered


def _as_path(spec: str) -> Path:
    """``spec``, not a registered name, as a path; a name that neither exists nor looks like
    a path (no folder, no log suffix) raises :class:`~slamkit.errors.UnknownNameError`
    listing the names (a misspelt name is not a missing file)."""
    p = Path(spec).expanduser()
    looks_like_path = os.sep in spec or "/" in spec or p.suffix.lower() in _LABEL_SUFFIXES
    if not (looks_like_path or p.exists()):
        raise UnknownNameError("dataset", spec, sorted(DATASETS))
    return p


def _registered_options(
    p: Path, options: Mapping[str, Any] | None, data_root: str | Path | None
) -> tuple[dict[str, Any], str | None]:
    """``options`` over the defaults of the registered bag ``p`` is (if it is one), and its
    registered name."""
    merged = dict(options or {})
    entry = registered_file(p, find_data_root(data_root)) if p.exists() else None
    if entry is None:
        return merged, None
    return {**entry.defaults, **merged}, entry.name


def load_data(
    spec: str,
    *,
    seed: int = 0,
    options: Mapping[str, Any] | None = None,
    data_root: str | Path | None = None,
) -> Dataset:
    """A registered data set by name (:func:`~slamkit.datasets.load_dataset`), else the
    laser log at the path ``spec`` (:func:`load_file`; see the module docstring for the
    registered bags). A name that is neither registered nor looks like a path raises
    :class:`~slamkit.errors.UnknownNameError` listing the names."""
    if spec in DATASETS:
        return load_dataset(spec, seed=seed, options=options, data_root=data_root)
    p = _as_path(spec)
    merged, registered = _registered_options(p, options, data_root)
    dataset = load_file(p, merged, seed=seed)
    if registered is not None:
        source = dataset.provenance
        assert source.path is not None and source.reader is not None  # load_file set them
        dataset = dataset.with_provenance(source.read_from(source.path, source.reader, registered))
    return dataset


def data_label(spec: str) -> str:
    """A short label of a ``--data`` value for folder names: a registered name as it is, a
    path as its file name without the log suffixes (``…/aces.bag`` → ``aces``,
    ``intel.log.gz`` → ``intel``)."""
    if spec in DATASETS:
        return spec
    name = Path(spec.rstrip("/\\")).name or spec
    stripped = True
    while stripped:
        stripped = False
        for suffix in _LABEL_SUFFIXES:
            if name.lower().endswith(suffix) and len(name) > len(suffix):
                name = name[: -len(suffix)]
                stripped = True
    return name
