"""Your own landmark data as one CSV file (``--data my_run.csv``).

The first line is the header ``kind,t,a,b,c``; each further line is one record, its meaning
given by ``kind`` (times in seconds, lengths in metres, angles in radians; ``#`` lines and
blank lines are skipped):

============  ======  ============  ==============  ===========================================
``kind``      ``t``   ``a``         ``b``           ``c``
============  ======  ============  ==============  ===========================================
``control``   time    v [m/s]       ω [rad/s]       dt [s]: applied over ``(t − dt, t]``
``odometry``  time    x             y               θ: the odometry pose at ``t``
``reading``   time    range (or x)  bearing (or y)  landmark id; empty or ``-1``: unknown
``truth``     time    x             y               θ: the true pose (optional)
``landmark``  empty   x             y               id: a true landmark (optional)
============  ======  ============  ==============  ===========================================

Motion comes as ``control`` rows or as ``odometry`` rows, not both. A ``reading`` row is one
landmark seen at ``t``; rows with the same time are one scan of the sensor, processed after
the motion at that time (:func:`slamkit.datasets.assemble.assemble_events`), whatever the order
of the lines. For a range-only or bearing-only sensor leave ``b`` empty; for a ``position``
sensor ``a, b`` are the landmark's ``(x, y)`` in the robot frame. ``landmark`` rows are the
truth the map is scored against and, with ``known_map = true``, the map localization uses.

The noise and limits the file cannot hold are :class:`LandmarkCsvOptions`, from a config
file's ``[dataset]`` table or ``--set dataset.KEY=VALUE``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np

from slamkit._validation import FloatArray, check_unique_ids
from slamkit.config import (
    Section,
    config_from_mapping,
    config_to_dict,
    finite_above,
    finite_at_least,
    setting,
)
from slamkit.datasets.arrays import landmark_dataset_from_arrays
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.stream import Dataset, LandmarkSensorSpec
from slamkit.errors import DatasetFormatError
from slamkit.maps import LandmarkMap

__all__ = ["CSV_HEADER", "LandmarkCsvOptions", "read_landmark_csv"]

CSV_HEADER = ("kind", "t", "a", "b", "c")
"""The header line of a landmark CSV file."""

_KINDS = ("control", "odometry", "reading", "truth", "landmark")


@dataclass(frozen=True)
class LandmarkCsvOptions(Section):
    """What a landmark CSV file needs besides its rows: the sensor and the noise."""

    SECTION: ClassVar[str] = "dataset"

    sensor: Literal["range-bearing", "range", "bearing", "position"] = "range-bearing"
    """What a reading measures: ``(range, bearing)``, range only, bearing only, or the
    landmark's ``(x, y)`` in the robot frame."""
    sigma_range: float = setting(0.1, finite_above(0.0), "a number > 0")
    """Standard deviation of a range (or of x and y for a ``position`` sensor) [m]."""
    sigma_bearing_deg: float = setting(2.0, finite_above(0.0), "a number > 0")
    """Standard deviation of a bearing [deg]."""
    max_range: float = setting(math.inf, lambda v: v > 0, "a number > 0 (inf: unlimited)")
    """The sensor's range [m] (estimators that count missed landmarks use it)."""
    min_range: float = setting(0.0, finite_at_least(0.0), "a number >= 0")
    """Landmarks closer than this [m] are not reported by the sensor."""
    fov_deg: float = setting(360.0, finite_above(0.0), "a number > 0")
    """The sensor's field of view, centred ahead [deg]."""
    sigma_v: float = setting(0.1, finite_above(0.0), "a number > 0")
    """Control rows: standard deviation of the speed [m/s]."""
    sigma_omega_deg: float = setting(5.0, finite_above(0.0), "a number > 0")
    """Control rows: standard deviation of the turn rate [deg/s]."""
    sigma_rot_deg: float = setting(2.0, finite_above(0.0), "a number > 0")
    """Odometry rows: standard deviation of each turn (rot1, rot2) of a motion [deg]."""
    sigma_trans: float = setting(0.05, finite_above(0.0), "a number > 0")
    """Odometry rows: standard deviation of the distance driven in a motion [m]."""
    initial_pose: tuple[float, float, float] | None = (0.0, 0.0, 0.0)
    """The prior pose ``(x, y, θ [rad])`` an estimator starts from; ``None``: no prior."""
    initial_sigma_xy: float = setting(0.01, finite_above(0.0), "a number > 0")
    """Standard deviation of the prior position [m]."""
    initial_sigma_theta_deg: float = setting(1.0, finite_above(0.0), "a number > 0")
    """Standard deviation of the prior heading [deg]."""
    known_map: bool = False
    """Give the ``landmark`` rows to localization estimators as the known map."""


def _cell(text: str, path: Path, line: int, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise DatasetFormatError(f"{what}: not a number: {text!r}", path, line) from None
    if not math.isfinite(value):
        raise DatasetFormatError(f"{what}: not finite: {text!r}", path, line)
    return value


def _rows(path: Path) -> dict[str, list[tuple[int, list[str]]]]:
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError:
        raise DatasetFormatError("not a text file (expected a landmark CSV file)", path) from None
    body = [(n, ln.strip()) for n, ln in enumerate(lines, 1) if ln.strip() and ln[:1] != "#"]
    if not body or tuple(c.strip() for c in body[0][1].split(",")) != CSV_HEADER:
        line = body[0][0] if body else 1
        raise DatasetFormatError(
            f"expected the header {','.join(CSV_HEADER)} of a landmark CSV file (docs/own-data.md)",
            path,
            line,
        )
    rows: dict[str, list[tuple[int, list[str]]]] = {k: [] for k in _KINDS}
    for n, text in body[1:]:
        cells = [c.strip() for c in text.split(",")]
        if len(cells) != len(CSV_HEADER):
            raise DatasetFormatError(f"expected 5 columns, got {len(cells)}", path, n)
        if cells[0] not in rows:
            raise DatasetFormatError(
                f"kind: expected one of {', '.join(_KINDS)}, got {cells[0]!r}", path, n
            )
        rows[cells[0]].append((n, cells))
    return rows


def read_landmark_csv(path: str | Path, options: Any = None, *, name: str | None = None) -> Dataset:
    """Read the landmark CSV file at ``path`` (see the module docstring) into a
    :class:`Dataset`; ``options`` a mapping or :class:`LandmarkCsvOptions`. A malformed line
    raises :class:`~slamkit.errors.DatasetFormatError` naming the file and line."""
    p = Path(path)
    opts = (
        options
        if isinstance(options, LandmarkCsvOptions)
        else config_from_mapping(LandmarkCsvOptions, options, "dataset")
    )
    rows = _rows(p)
    dim = 2 if opts.sensor in ("range-bearing", "position") else 1
    readings = _table(rows, "reading", dim, p)
    if readings.shape[0] == 0:
        raise DatasetFormatError("no reading rows: nothing to localize or map with", p)
    ids = []
    for n, c in rows["reading"]:
        ids.append(-1 if c[4] in ("", "-1") else int(_cell(c[4], p, n, "id")))
    if rows["control"] and rows["odometry"]:
        n = rows["odometry"][0][0]
        raise DatasetFormatError("control and odometry rows in one file: give one", p, n)
    if not (rows["control"] or rows["odometry"]):
        raise DatasetFormatError("no control or odometry rows: the robot never moves", p)
    sensor = _sensor(opts, identities=bool(np.all(np.asarray(ids) >= 0)))
    motion = _motion(rows, opts, p)
    truth = _table(rows, "truth", 3, p) if rows["truth"] else None
    if truth is not None:
        truth = truth[np.argsort(truth[:, 0], kind="stable")]
    landmarks = _landmarks(rows, p) if rows["landmark"] else None
    s, st = opts.initial_sigma_xy, math.radians(opts.initial_sigma_theta_deg)
    has_prior = opts.initial_pose is not None
    dataset = landmark_dataset_from_arrays(
        sensor=sensor,
        reading_times=readings[:, 0],
        readings=readings[:, 1:],
        reading_ids=np.asarray(ids, dtype=np.int64),
        **motion,
        initial_pose=None if not has_prior else np.asarray(opts.initial_pose, dtype=float),
        initial_cov=np.diag([s * s, s * s, st * st]) if has_prior else None,
        truth_times=None if truth is None else truth[:, 0],
        truth_poses=None if truth is None else truth[:, 1:],
        true_landmarks=landmarks,
        known_landmarks=landmarks if opts.known_map else None,
        name=name or p.stem,
        description=f"landmark CSV file {p.name}",
        metadata={"kind": "file"},
    )
    return dataset.with_provenance(Provenance(options=config_to_dict(opts)))


def _table(
    rows: dict[str, list[tuple[int, list[str]]]], kind: str, cols: int, p: Path
) -> FloatArray:
    """The rows of ``kind`` as numbers ``(n, 1 + cols)``: the time and ``cols`` values."""
    out = [
        [_cell(c[1], p, n, "t")]
        + [_cell(v, p, n, h) for v, h in zip(c[2 : 2 + cols], "abc"[:cols], strict=True)]
        for n, c in rows[kind]
    ]
    return np.asarray(out, dtype=float).reshape(-1, 1 + cols)


def _sensor(opts: LandmarkCsvOptions, *, identities: bool) -> LandmarkSensorSpec:
    if opts.sensor == "range-bearing":
        noise = np.diag([opts.sigma_range**2, math.radians(opts.sigma_bearing_deg) ** 2])
    elif opts.sensor == "bearing":
        noise = np.array([[math.radians(opts.sigma_bearing_deg) ** 2]])
    elif opts.sensor == "range":
        noise = np.array([[opts.sigma_range**2]])
    else:
        noise = np.eye(2) * opts.sigma_range**2
    return LandmarkSensorSpec(
        opts.sensor,
        noise,
        max_range=opts.max_range,
        min_range=opts.min_range,
        fov=math.radians(opts.fov_deg),
        identities=identities,
    )


def _motion(
    rows: dict[str, list[tuple[int, list[str]]]], opts: LandmarkCsvOptions, p: Path
) -> dict[str, Any]:
    """The motion arguments of :func:`landmark_dataset_from_arrays`: the control rows with
    the unicycle's noise, or the odometry rows with the odometry model's."""
    if rows["control"]:
        ctl = _table(rows, "control", 3, p)
        return {
            "control_times": ctl[:, 0],
            "controls": ctl[:, 1:3],
            "control_dt": ctl[:, 3],
            "motion_noise_cov": np.diag([opts.sigma_v**2, math.radians(opts.sigma_omega_deg) ** 2]),
        }
    o = _table(rows, "odometry", 3, p)
    rot = math.radians(opts.sigma_rot_deg) ** 2
    return {
        "odometry_times": o[:, 0],
        "odometry_poses": o[:, 1:],
        "motion_noise_cov": np.diag([rot, opts.sigma_trans**2, rot]),
    }


def _landmarks(rows: dict[str, list[tuple[int, list[str]]]], p: Path) -> LandmarkMap:
    """The landmark rows ``x, y, id`` as a map (integer, unique ids)."""
    lm = np.asarray(
        [
            [_cell(v, p, n, h) for v, h in zip(c[2:5], "abc", strict=True)]
            for n, c in rows["landmark"]
        ]
    )
    lines = [n for n, _ in rows["landmark"]]
    for n, ident in zip(lines, lm[:, 2].tolist(), strict=True):
        if not float(ident).is_integer():
            raise DatasetFormatError(f"landmark id: expected an integer, got {ident}", p, n)
    check_unique_ids(lm[:, 2].astype(np.int64), lines, "landmark id", p)
    return LandmarkMap(lm[:, :2], lm[:, 2].astype(np.int64))
