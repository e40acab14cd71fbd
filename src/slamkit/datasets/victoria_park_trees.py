"""Victoria Park's trees extracted by slamkit from the raw laser: a landmark data set.

The raw-laser release (:mod:`slamkit.datasets.victoria_park_laser`: 7,230 scans of 361
beams, the truck's speed and steering, GPS) made into range-bearing readings of tree trunks
by :func:`slamkit.features.extract_trees`, scan by scan: the same controls, the same GPS
and the same clock as ``victoria-park-laser`` (seconds from the start of the log; the
published detections of ``victoria-park`` run 20.967 s ahead). Each trunk's centre, found
in the laser frame, becomes the reading ``(|p|, atan2(p_y, p_x))`` of the point ``p`` in
the vehicle frame (rear-axle centre; laser at ``(3.78, 0.50)`` m), exactly as
``victoria-park`` moves its published detections
(:func:`~slamkit.datasets.victoria_park.laser_to_vehicle`), so the same
:class:`~slamkit.models.RangeBearing` model applies. The trunks of one scan are one
:class:`LandmarkReadings` event at the scan's time, after the control that ends then (the
raw loader cuts the controls at the scan times). Ids are ``-1``: there is no association to
score against. Each trunk's diameter, the signature, is not a reading (the estimators read
``(range, bearing)``); :func:`scan_trees` returns it with every detection, and the data
set's metadata counts the detections and gives their median diameter.

The readings' nominal noise is ``victoria-park``'s (``sigma_range = 0.1`` m,
``sigma_bearing = 0.01`` rad); how these detections compare with the published ones (how
many are reproduced within 0.5 m, how many are extra) and how the estimators fare on them is
measured in ``docs/estimators/tree_extraction.md``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from slamkit._validation import FloatArray
from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.assemble import assemble_events, reading_events
from slamkit.datasets.stream import (
    Control,
    Dataset,
    LandmarkReadings,
    LandmarkSensorSpec,
    LaserScan,
    measured_detection_range,
)
from slamkit.datasets.victoria_park import LASER_MAX_RANGE, LASER_OFFSET, laser_to_vehicle
from slamkit.datasets.victoria_park_laser import (
    VICTORIA_PARK_LASER_FILES,
    load_victoria_park_laser,
)
from slamkit.errors import ConfigError, InputError
from slamkit.features import TreeDetections, TreeExtractorConfig, extract_trees

__all__ = [
    "CLOCK_OFFSET_S",
    "DetectionMatch",
    "ScanTrees",
    "VictoriaParkTreesOptions",
    "load_victoria_park_trees",
    "match_published",
    "scan_trees",
]


@dataclass(frozen=True)
class VictoriaParkTreesOptions:
    """Options of :func:`load_victoria_park_trees` (units: seconds, metres, radians)."""

    max_duration_s: float | None = None
    """Keep only the first this many seconds after the first speed/steering sample."""
    steering_offset: float = 0.0
    """Added to every steering reading [rad], as ``victoria-park``'s option."""
    sigma_range: float = 0.1
    """Nominal range noise of a reading [m] (``victoria-park``'s)."""
    sigma_bearing: float = 0.01
    """Nominal bearing noise of a reading [rad] (``victoria-park``'s)."""

    def __post_init__(self) -> None:
        for name in ("sigma_range", "sigma_bearing"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a number > 0, got {getattr(self, name)}")


@dataclass(frozen=True)
class ScanTrees:
    """The trunks of one scan at time ``t`` [s], in the laser frame."""

    t: float
    trees: TreeDetections


def scan_trees(laser: Dataset, config: TreeExtractorConfig | None = None) -> list[ScanTrees]:
    """The trunks of every scan of a laser data set (``victoria-park-laser``), in time
    order, scans without a trunk included (empty)."""
    if laser.laser is None:
        raise InputError(f"scan_trees: data set {laser.name!r} has no laser")
    angles = laser.laser.beam_angles
    return [
        ScanTrees(ev.t, extract_trees(ev.ranges, angles, config))
        for ev in laser.events
        if isinstance(ev, LaserScan)
    ]


CLOCK_OFFSET_S = 20.967
"""``victoria-park``'s clock minus the raw laser's [s]
(:mod:`slamkit.datasets.victoria_park_laser`)."""


@dataclass(frozen=True)
class DetectionMatch:
    """Our trunks against the published detections at the scans both have: ``scans``
    compared, ``published`` detections there, ``reproduced`` of them with one of ours
    within ``radius``, ``ours`` detections there and ``extra`` of ours with no published
    one within ``radius`` [m]; ``not_compared``: published stamps where we found no trunk."""

    scans: int
    published: int
    reproduced: int
    ours: int
    extra: int
    radius: float
    not_compared: int = 0

    def as_dict(self) -> dict[str, float | int]:
        return {
            "scans": self.scans,
            "published": self.published,
            "reproduced": self.reproduced,
            "ours": self.ours,
            "extra": self.extra,
            "radius_m": self.radius,
            "not_compared": self.not_compared,
        }


def _xy(z: FloatArray) -> FloatArray:
    return np.column_stack([z[:, 0] * np.cos(z[:, 1]), z[:, 0] * np.sin(z[:, 1])])


def match_published(
    ours: Dataset, published: Dataset, *, radius: float = 0.5, tolerance_s: float = 0.005
) -> DetectionMatch:
    """Compare the readings of ``victoria-park-trees`` (``ours``) with those of
    ``victoria-park`` (``published``) scan by scan, in the vehicle frame: a published
    stamp minus :data:`CLOCK_OFFSET_S` within ``tolerance_s`` of a readings event of ours
    is compared; a published stamp with none of ours there (we found no trunk in that scan)
    is counted in ``not_compared``."""
    mine = {round(ev.t, 3): ev.z for ev in ours.events if isinstance(ev, LandmarkReadings)}
    t_mine = np.array(sorted(mine))
    scans = published_n = reproduced = ours_n = extra = not_compared = 0
    for ev in published.events:
        if not isinstance(ev, LandmarkReadings) or t_mine.size == 0:
            continue
        t = ev.t - CLOCK_OFFSET_S
        k = int(np.argmin(np.abs(t_mine - t)))
        if abs(t_mine[k] - t) > tolerance_s:
            not_compared += 1
            continue
        p, q = _xy(ev.z), _xy(mine[float(t_mine[k])])
        dist = np.linalg.norm(p[:, None, :] - q[None, :, :], axis=2)
        scans += 1
        published_n += p.shape[0]
        ours_n += q.shape[0]
        reproduced += int(np.count_nonzero(dist.min(axis=1) < radius))
        extra += int(np.count_nonzero(dist.min(axis=0) >= radius))
    return DetectionMatch(scans, published_n, reproduced, ours_n, extra, radius, not_compared)


def _readings(found: list[ScanTrees]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Stamps ``(K,)``, vehicle-frame readings ``(K, 2)`` and diameters ``(K,)``."""
    t = np.concatenate([np.full(len(s.trees), s.t) for s in found] + [np.zeros(0)])
    rng = np.concatenate([s.trees.ranges for s in found] + [np.zeros(0)])
    # The laser's bearings run from -pi/2 (right) to pi/2; laser_to_vehicle counts from
    # the right, [0, pi].
    brg = np.concatenate([s.trees.bearings for s in found] + [np.zeros(0)]) + np.pi / 2.0
    diam = np.concatenate([s.trees.diameters for s in found] + [np.zeros(0)])
    return t, laser_to_vehicle(rng, brg, LASER_OFFSET), diam


def load_victoria_park_trees(
    options: Mapping[str, Any] | None = None,
    *,
    seed: int = 0,
    data_root: Path | None = None,
) -> Dataset:
    """Load Victoria Park's raw laser as a landmark data set: the trunks
    :func:`~slamkit.features.extract_trees` finds in each scan as range-bearing readings
    from the rear-axle centre (ids ``-1``), the raw loader's Ackermann controls and GPS.

    ``options`` are the fields of :class:`VictoriaParkTreesOptions`; ``seed`` is unused;
    errors are those of :func:`~slamkit.datasets.victoria_park_laser.
    load_victoria_park_laser` (a malformed line: :class:`DatasetFormatError` with file and
    line). See the module docstring.
    """
    opts = config_from_mapping(VictoriaParkTreesOptions, options, "victoria-park-trees")
    laser = load_victoria_park_laser(
        {"max_duration_s": opts.max_duration_s, "steering_offset": opts.steering_offset},
        data_root=data_root,
    )
    found = scan_trees(laser)
    t, z, diam = _readings(found)
    readings = reading_events(t, z, np.full(t.size, -1, dtype=np.int64))
    controls = [ev for ev in laser.events if isinstance(ev, Control)]
    events = assemble_events(controls, readings)
    a, b = LASER_OFFSET
    sensor = LandmarkSensorSpec(
        kind="range-bearing",
        noise_cov=np.diag([opts.sigma_range**2, opts.sigma_bearing**2]),
        max_range=LASER_MAX_RANGE + float(np.hypot(a, b)),
        fov=np.pi,
        identities=False,
        offset=(a, b),
    )
    reading = laser.reading
    if reading is not None:
        note = (
            f"{t.size} trunks found in {len(readings)} of {len(found)} scans (median "
            f"diameter {float(np.median(diam)) if diam.size else float('nan'):.2f} m)"
        )
        reading = replace(reading, notes=(*reading.notes, note))
    return Dataset(
        name="victoria-park-trees",
        events=events,
        motion=laser.motion,
        landmark_sensor=replace(sensor, detection_range=measured_detection_range(events, sensor)),
        initial_pose=np.zeros(3),
        initial_cov=np.zeros((3, 3)),
        truth=laser.truth,
        description=_DESCRIPTION,
        metadata=_metadata(opts, laser, found, diam, len(readings)),
        reading=reading,
    )


_DESCRIPTION = (
    "Victoria Park: tree trunks slamkit extracts from the raw laser scans as range-bearing "
    "readings from the rear axle (ids unknown), 40 Hz Ackermann speed/steering, GPS"
)


def _metadata(
    opts: VictoriaParkTreesOptions,
    laser: Dataset,
    found: list[ScanTrees],
    diam: FloatArray,
    n_events: int,
) -> dict[str, Any]:
    fitted = sum(int(np.count_nonzero(s.trees.fitted)) for s in found)
    return {
        "kind": "real",
        "source": "Victoria Park, ACFR raw laser; trunks extracted by slamkit.features",
        "files": list(VICTORIA_PARK_LASER_FILES),
        "time_origin": laser.metadata.get("time_origin", ""),
        "scans": len(found),
        "detections": int(diam.size),
        "reading_events": n_events,
        "circle_fits": fitted,
        "median_diameter_m": float(np.median(diam)) if diam.size else None,
        "extractor": config_to_dict(TreeExtractorConfig()),
        "gps_fixes": laser.metadata.get("gps_fixes"),
        "cut_at_s": laser.metadata.get("cut_at_s"),
        "options": config_to_dict(opts),
    }
