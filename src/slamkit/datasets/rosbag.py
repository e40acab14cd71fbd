"""ROS bags of 2D laser scans and wheel odometry → :class:`~slamkit.datasets.Dataset`.

Read without a ROS install through the ``rosbags`` package (``pip install 'slamkit[laser]'``),
whose :class:`rosbags.highlevel.AnyReader` opens

* a ROS 1 bag (``*.bag``, any compression),
* a ROS 2 bag: its folder (with ``metadata.yaml``), or one of its storage files on its own —
  ``*.db3`` (SQLite) or ``*.mcap``. rosbags 0.11 reads a standalone ``.mcap`` file without a
  ``metadata.yaml`` (the message definitions are in the file); a standalone ``.db3`` from an
  old recorder may lack them, then the ROS 2 message definitions of rosbags' latest type store
  are used.

Only the scan and odometry topics are deserialised (plus ``/tf_static``, and ``/tf`` when the
laser's mounting is not static or the odometry comes from it).

Conversion (all in one pass over arrays once the messages are read):

* ``sensor_msgs/msg/LaserScan`` on ``scan_topic`` → one :class:`LaserScan` per message at its
  header stamp (``sec + nanosec·1e-9``, float64). Beam ``i`` points at
  ``angle_min + i·angle_increment`` in the laser's frame: the increment and the number of
  ranges win over ``angle_max``, as in gmapping, slam_toolbox and Cartographer. An
  ``angle_max`` up to :data:`~slamkit.datasets.rosbag_checks.ANGLE_MAX_TOLERANCE` (1.5)
  increments from the last beam's angle is read (drivers and converters often write it a beam
  off) and noted once for the bag; further off is an error. Every scan must have the first
  scan's geometry.
  Ranges ``>= range_max`` or ``+inf`` are no return, and so are ranges below ``range_min`` or
  ``-inf`` (REP 117: too close): stored as exactly ``max_range``, slamkit's convention. A NaN
  or a negative finite range is an error (lenient: that beam becomes no return, counted).
* ``nav_msgs/msg/Odometry`` on ``odom_topic`` → the robot's pose ``(x, y, yaw)`` in the
  odometry frame (yaw from the quaternion), interpolated to each scan stamp under the rules of
  :mod:`slamkit.datasets.raw_odometry` → one :class:`Odometry` event per scan, just before it.
  A bag without an odometry topic (``odometry_source="auto"``), or ``odometry_source="tf"``:
  the transforms ``odom_frame → base_frame`` on ``/tf`` over the whole bag (directly, or
  ``odom → X`` then a fixed ``X → … → base_link`` on ``/tf_static``) take the messages' place
  on the same path; ``metadata["odometry_from"]`` and the reading summary's notes say so.
* The laser's mounting on the robot: the transform from the odometry's child frame (or
  ``base_frame``) to the scan's ``frame_id``, chained through ``/tf_static`` (else the first
  10 s of ``/tf``) → :attr:`LaserSpec.mounting` ``(x, y, yaw)``. A tilted mounting (roll or
  pitch) is refused; none found → the laser at the robot's origin (said in the metadata).

Errors: a missing topic, a topic of another message type, a bag that cannot be read
(truncated, corrupt, unknown storage), bad geometry, NaN/negative ranges, stamps out of
order, a scan inside an odometry gap → :class:`~slamkit.errors.DatasetFormatError` naming the
bag, and the topic and message index (0-based, in bag order) where one is at fault. With
``lenient=True`` the bad messages are dropped (bad beams marked no return) and counted in
``metadata``. :attr:`Dataset.reading <slamkit.datasets.Dataset.reading>` says what was read,
dropped (by reason), repaired and noted; a read that would drop more than 10% of the scans
(lenient or not: bad messages, scans outside the odometry) is an error instead
(:func:`~slamkit.datasets.reading.check_dropped_share`).

The Freiburg benchmark's three raw logs are registered here as ``intel-raw``, ``aces-raw`` and
``fr079-raw``, with the benchmark's reference relations as ground truth.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.paths import data_root as resolve_data_root
from slamkit.datasets.paths import require_file
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.raw_odometry import (
    DEFAULT_MAX_ODOM_GAP,
    RAW_ODOMETRY_SIGMA_ROT_DEG,
    RAW_ODOMETRY_SIGMA_TRANS,
    check_gap_option,
    increasing_mask,
    odometry_at_scans,
    raw_laser_dataset,
    raw_odometry_cov,
    repeat_mask,
    signed_by_speed,
)
from slamkit.datasets.reading import ReadingSummary, check_dropped_share
from slamkit.datasets.relations import Relations, read_relations
from slamkit.datasets.rosbag_checks import Problems, check_geometry, clean_ranges, header_stamps
from slamkit.datasets.rosbag_read import BagContents, OdometryRequest, read_bag
from slamkit.datasets.stream import Dataset, LaserSpec
from slamkit.errors import ConfigError, DatasetFormatError

__all__ = [
    "RosbagOptions",
    "load_aces_raw",
    "load_fr079_raw",
    "load_intel_raw",
    "read_rosbag",
]


def _check_nonneg(value: float, name: str) -> None:
    if not (math.isfinite(value) and value >= 0):
        raise ConfigError(f"{name}: expected a finite number >= 0, got {value!r}")


DEFAULT_ODOM_TOPIC = "/odom"


@dataclass(frozen=True)
class RosbagOptions:
    """How to read a ROS bag of laser scans and odometry. Units: metres, seconds, radians
    unless the name says degrees."""

    scan_topic: str = "/scan"
    """Topic of the ``sensor_msgs/msg/LaserScan`` messages."""
    odom_topic: str | None = DEFAULT_ODOM_TOPIC
    """Topic of the ``nav_msgs/msg/Odometry`` messages (the robot's raw odometry); None: read
    no odometry. Left at the default on a bag without any odometry topic, the bag is read
    with the odometry of ``/tf`` (``odometry_source``), else without odometry (scans only;
    the description says so) instead of being refused."""
    odometry_source: Literal["auto", "topic", "tf"] = "auto"
    """Where the odometry comes from: ``"topic"``, ``odom_topic``; ``"tf"``, the transforms
    ``odom_frame → base_frame`` on ``/tf`` over the whole bag (what many bags have instead
    of an odometry topic); ``"auto"``, the topic when the bag has one, else ``/tf`` when it
    holds that transform, else none."""
    odom_frame: str = "odom"
    """The odometry frame of the ``/tf`` odometry (REP 105's ``odom``)."""
    max_odom_gap: float = DEFAULT_MAX_ODOM_GAP
    """A scan between two odometry messages further apart than this [s] is an error
    (lenient: dropped); ``inf``: no limit."""
    max_range: float | None = None
    """The no-return range stored in the LaserSpec [m]; None: the first scan's
    ``range_max``. Readings at or beyond it (or their message's ``range_max``) are no
    return."""
    mounting: tuple[float, float, float] | None = None
    """The laser's pose ``(x, y, yaw)`` on the robot [m, m, rad]; None: from the bag's tf."""
    base_frame: str | None = None
    """The robot's frame for the mounting and the ``/tf`` odometry; None: the odometry's
    ``child_frame_id`` (``base_link`` for the ``/tf`` odometry)."""
    stamps: Literal["header", "bag"] = "header"
    """Time of a message: its header stamp, or the time it was recorded in the bag."""
    range_sigma: float = 0.01
    """Nominal range noise stored in the LaserSpec [m] (the bag does not say)."""
    odometry_sigma_trans: float = RAW_ODOMETRY_SIGMA_TRANS
    """Nominal per-step translation noise of the odometry [m] (for the MotionSpec)."""
    odometry_sigma_rot_deg: float = RAW_ODOMETRY_SIGMA_ROT_DEG
    """Nominal per-step rotation noise of the odometry [deg] (for the MotionSpec)."""
    odometry_direction: Literal["pose", "twist"] = "pose"
    """Which way the odometry travels: ``"pose"``, as its poses say; ``"twist"``, each step
    between two messages backward where the twist's forward speed (``linear.x``) is
    negative (:func:`~slamkit.datasets.raw_odometry.signed_by_speed`): for a bag whose poses
    were integrated from the unsigned speed (Freiburg 079's)."""
    lenient: bool = False
    """Drop bad messages (mark bad beams no return) and count them instead of raising."""
    max_duration_s: float | None = None
    """Keep only the scans of the first this many seconds after the first scan, and the
    reference relations within them (all when ``None``): studies on a part of a long log."""

    def __post_init__(self) -> None:
        for name in ("scan_topic", "odom_topic"):
            value = getattr(self, name)
            if (value is not None and not value) or (name == "scan_topic" and value is None):
                raise ConfigError(f"{name}: expected a topic name, got {value!r}")
        check_gap_option(self.max_odom_gap)
        mr = self.max_range
        if mr is not None and not (math.isfinite(mr) and mr > 0):
            raise ConfigError(f"max_range: expected a number > 0 or nothing, got {mr!r}")
        m = self.mounting
        if m is not None and (len(m) != 3 or not all(math.isfinite(v) for v in m)):
            raise ConfigError(f"mounting: expected three finite numbers (x, y, yaw), got {m!r}")
        if self.odometry_direction not in ("pose", "twist"):
            raise ConfigError(
                f"odometry_direction: expected 'pose' or 'twist', got {self.odometry_direction!r}"
            )
        if self.odometry_source not in ("auto", "topic", "tf"):
            raise ConfigError(
                f"odometry_source: expected 'auto', 'topic' or 'tf', got {self.odometry_source!r}"
            )
        for name in ("odom_frame", "base_frame"):
            value = getattr(self, name)
            if (value is not None and not str(value).strip("/")) or (
                name == "odom_frame" and value is None
            ):
                raise ConfigError(f"{name}: expected a frame name, got {value!r}")
        if self.stamps not in ("header", "bag"):
            raise ConfigError(f"stamps: expected 'header' or 'bag', got {self.stamps!r}")
        for name in ("range_sigma", "odometry_sigma_trans", "odometry_sigma_rot_deg"):
            _check_nonneg(getattr(self, name), name)
        d = self.max_duration_s
        if d is not None and not (math.isfinite(d) and d > 0):
            raise ConfigError(f"max_duration_s: expected a number > 0 [s] or nothing, got {d!r}")


def _odometry(
    bag: BagContents, opts: RosbagOptions, problems: Problems
) -> tuple[FloatArray, FloatArray, int]:
    """Odometry stamps ``(M,)`` and poses ``(M, 3)``, checked; and the repeats dropped."""
    o = bag.odometry
    topic = bag.odometry_from or str(bag.odometry_topic)
    t = o.bag_times if opts.stamps == "bag" else header_stamps(o.sec, o.nsec)
    q = o.orientation  # (M, 4) x y z w
    with np.errstate(over="ignore", invalid="ignore"):  # a huge component: inf, refused
        norm = np.linalg.norm(q, axis=1)
    ok = np.isfinite(o.position).all(axis=1) & np.isfinite(norm) & (norm > 1e-9)
    problems.report(
        "bad_odometry", topic, np.flatnonzero(~ok), "pose not finite or quaternion of norm 0"
    )
    qx, qy, qz, qw = (q[:, k] / np.where(ok, norm, 1.0) for k in range(4))
    # yaw of a unit quaternion: atan2(2 (w z + x y), 1 - 2 (y² + z²)); the rows not ok (a
    # huge or zero norm) may overflow here and are dropped below
    with np.errstate(over="ignore", invalid="ignore"):
        yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    poses = np.column_stack([o.position[:, 0], o.position[:, 1], yaw])
    idx = np.flatnonzero(ok)
    t, poses = t[idx], poses[idx]
    repeats = repeat_mask(t, poses)
    idx, t, poses = idx[~repeats], t[~repeats], poses[~repeats]
    order = increasing_mask(t)
    problems.report(
        "odometry_out_of_order",
        topic,
        idx[~order],
        "stamp not later than the messages before it (out of order)",
    )
    t, poses = t[order], poses[order]
    if opts.odometry_direction == "twist":
        if bag.odometry_topic != opts.odom_topic:
            raise DatasetFormatError(
                f"odometry_direction 'twist' needs the twist of an odometry topic; the "
                f"odometry is from {bag.odometry_from}, which has none",
                problems.path,
            )
        poses = signed_by_speed(poses, o.speed[idx[order]])
    return t, poses, int(np.count_nonzero(repeats))


def _odometry_at_scans(
    bag: BagContents,
    opts: RosbagOptions,
    t: FloatArray,
    index: NDArray[np.int64],
    problems: Problems,
) -> tuple[FloatArray | None, NDArray[np.bool_], dict[str, int], int]:
    """The odometry at the scan stamps ``t`` (None without odometry), which scans to keep,
    the dropped counts, the repeated odometry messages dropped."""
    if bag.odometry_topic is None:
        return None, np.ones(t.size, dtype=bool), {}, 0
    topic = bag.odometry_from
    odom_t, odom_poses, repeats = _odometry(bag, opts, problems)
    at = odometry_at_scans(t, odom_t, odom_poses, opts.max_odom_gap)
    if at.in_gap.any():
        i = int(np.argmax(at.in_gap))
        problems.report(
            "odometry_gap",
            opts.scan_topic,
            index[at.in_gap],
            f"scan at t={t[i]:.9f} lies in a {at.gap[i]:.3f} s gap of {topic} "
            f"(max_odom_gap {opts.max_odom_gap} s; raise it or set lenient)",
        )
    if not at.keep.any():
        raise DatasetFormatError(
            f"no scan on {opts.scan_topic} lies within the odometry on {topic} "
            f"({odom_t[0]:.3f}..{odom_t[-1]:.3f} s)",
            problems.path,
        )
    return at.poses, at.keep, at.dropped, repeats


@dataclass(frozen=True)
class _Scans:
    """The scans the geometry check and the order kept (indices into the bag's scan
    messages, stamps, raw ranges), how many there were before the cut, and the beams."""

    index: NDArray[np.int64]
    t: FloatArray
    raw: FloatArray
    n_before_cut: int
    n_beams: int


def _convert(
    bag: BagContents, opts: RosbagOptions, path: Path, name: str, relations: Relations | None
) -> Dataset:
    problems = Problems(path, opts.lenient)
    s = bag.scans
    if s.beam_counts.size == 0:
        raise DatasetFormatError(f"no messages on {opts.scan_topic}", path)
    if bag.odometry_topic is not None and bag.odometry.sec.size == 0:
        raise DatasetFormatError(f"no messages on {bag.odometry_from}", path)
    ok, angle_note = check_geometry(bag, opts.scan_topic, problems)
    scans = _ordered_scans(bag, opts, ok, problems)
    index, t = scans.index, scans.t
    if relations is not None and opts.max_duration_s is not None:
        relations = relations.until(float(t[-1]))
    max_range = opts.max_range if opts.max_range is not None else float(s.range_max[index[0]])
    ranges, reading_counts = clean_ranges(
        scans.raw, s.range_min[index], s.range_max[index], max_range, index,
        opts.scan_topic, problems,
    )  # fmt: skip
    odometry, keep, dropped, repeats = _odometry_at_scans(bag, opts, t, index, problems)
    angles = s.angle_min[index[0]] + np.arange(scans.n_beams) * s.angle_increment[index[0]]
    mounting, mounting_from = _mounting(bag, opts, path)
    laser = LaserSpec(angles, max_range, opts.range_sigma, mounting=mounting)
    n_kept = int(keep.sum())
    notes = [n for n in (angle_note, _odometry_note(bag, problems)) if n]
    if index.size < scans.n_before_cut:
        notes.append(
            f"cut after the first {opts.max_duration_s:g} s: {index.size} of "
            f"{scans.n_before_cut} scans"
        )
    reading = _summary(path, int(s.beam_counts.size), n_kept, problems, dropped, notes)
    check_dropped_share(
        path, reading.records, sum(reading.dropped.values()), reasons=reading.dropped
    )
    return raw_laser_dataset(
        name=name,
        times=t[keep],
        odometry=odometry,
        ranges=ranges[keep],
        laser=laser,
        motion_cov=raw_odometry_cov(opts.odometry_sigma_trans, opts.odometry_sigma_rot_deg),
        description=_description(bag, path, opts.scan_topic, n_kept, scans.n_beams, odometry),
        metadata=_metadata(bag, opts, path, scans.n_beams, laser, problems)
        | {
            "scans": n_kept,
            "odometry_repeats_dropped": repeats,
            "max_range": max_range,
            "mounting_from": mounting_from,
            "dropped": dropped,
            "readings": reading_counts,
        },
        relations=relations,
        reading=reading,
        provenance=Provenance(options=config_to_dict(opts)),
    )


def _metadata(
    bag: BagContents,
    opts: RosbagOptions,
    path: Path,
    n_beams: int,
    laser: LaserSpec,
    problems: Problems,
) -> dict[str, Any]:
    """What the bag held and how it was read (the counts of the conversion are added by
    the caller)."""
    return {
        "kind": "real",
        "format": "rosbag1" if bag.ros1 else ("mcap" if path.suffix == ".mcap" else "rosbag2"),
        "file": path.name,
        "scan_messages": int(bag.scans.beam_counts.size),
        "odometry_topic": bag.odometry_topic,
        "odometry_from": bag.odometry_from or None,
        "odometry_messages": int(bag.odometry.sec.size),
        "beams": n_beams,
        "laser_frame": bag.scan_frame,
        "mounting": list(laser.mounting),
        "lenient": {"counts": dict(problems.counts), "first": list(problems.first)},
        "topics": dict(bag.topics),
        "cut_at_s": opts.max_duration_s,
    }


def _ordered_scans(
    bag: BagContents, opts: RosbagOptions, ok: NDArray[np.bool_], problems: Problems
) -> _Scans:
    """The scans of good geometry (``ok``) whose stamps (the header's or the bag's) increase
    (others reported), cut after ``max_duration_s``."""
    s, topic = bag.scans, opts.scan_topic
    index = np.flatnonzero(ok)
    if index.size == 0:
        raise DatasetFormatError(f"no usable scans on {topic}", problems.path)
    n_beams = int(s.beam_counts[index[0]])
    raw = np.vstack([s.ranges[i] for i in index.tolist()]).astype(np.float64)
    t_all = s.bag_times if opts.stamps == "bag" else header_stamps(s.sec, s.nsec)
    t = t_all[index]
    order = increasing_mask(t)
    if not order.all():
        problems.report(
            "scans_out_of_order",
            topic,
            index[~order],
            f"stamp {t[~order][0]:.9f} not later than the scans before it (out of order)",
        )
    index, t, raw = index[order], t[order], raw[order]
    n_before_cut = index.size
    if opts.max_duration_s is not None:
        within = t <= t[0] + opts.max_duration_s
        index, t, raw = index[within], t[within], raw[within]
    return _Scans(index, t, raw, n_before_cut, n_beams)


def _description(
    bag: BagContents, path: Path, topic: str, n_kept: int, n_beams: int, odometry: Any
) -> str:
    motion = (
        f"raw odometry ({bag.odometry_from})"
        if odometry is not None
        else "no odometry (scan matching alone)"
    )
    version = "ROS 1" if bag.ros1 else "ROS 2"
    return f"{version} bag {path.name}: {n_kept} scans × {n_beams} beams ({topic}), {motion}"


SCAN_DROPS = {
    "geometry": "bad geometry",
    "scans_out_of_order": "stamp out of order",
    "before_odometry": "before the odometry",
    "after_odometry": "after the odometry",
    "odometry_gap": "in an odometry gap",
}
"""The reader's counts of dropped scans (``metadata["lenient"]["counts"]`` and
``metadata["dropped"]``) → the reasons of the :class:`ReadingSummary`."""


def _summary(
    path: Path,
    records: int,
    used: int,
    problems: Problems,
    dropped: Mapping[str, int],
    notes: list[str],
) -> ReadingSummary:
    """What reading the bag did to its scans: drops and repairs by reason, and notes."""
    counts = {**problems.counts, **dropped}
    by_reason = {SCAN_DROPS[k]: n for k, n in counts.items() if k in SCAN_DROPS and n}
    bad_beams = problems.counts.get("invalid_readings", 0)
    repaired = {"NaN or negative ranges set to no return": bad_beams} if bad_beams else {}
    return ReadingSummary(
        file=path.name,
        records=records,
        used=used,
        dropped=by_reason,
        repaired=repaired,
        notes=tuple(notes),
    )


def _odometry_note(bag: BagContents, problems: Problems) -> str:
    """Where the odometry came from when that is not its topic, and the odometry messages a
    lenient read dropped."""
    parts = []
    if bag.odometry_topic is None:
        parts.append("no odometry: the scans alone")
    elif bag.odometry_from != bag.odometry_topic:
        parts.append(f"odometry from {bag.odometry_from}")
    bad = problems.counts.get("bad_odometry", 0) + problems.counts.get("odometry_out_of_order", 0)
    if bad:
        parts.append(f"{bad} odometry messages dropped (bad pose or out of order)")
    return "; ".join(parts)


def _mounting(
    bag: BagContents, opts: RosbagOptions, path: Path
) -> tuple[tuple[float, float, float], str]:
    if opts.mounting is not None:
        x, y, yaw = opts.mounting
        return (x, y, yaw), "option mounting"
    base = (opts.base_frame or bag.odom_child_frame or "base_link").strip("/")
    laser = bag.scan_frame.strip("/")
    if base == laser or not laser:
        return (0.0, 0.0, 0.0), "the scans are in the robot's frame"
    chain = bag.transform(base, laser)
    if chain is None:
        return (0.0, 0.0, 0.0), f"no tf from {base!r} to {laser!r}: laser at the robot origin"
    (x, y, yaw), tilt, source = chain
    if not all(math.isfinite(v) for v in (x, y, yaw, tilt)):
        raise DatasetFormatError(
            f"the transform {base} → {laser} on {source} is not finite "
            f"(x, y, yaw = {x!r}, {y!r}, {yaw!r}); give mounting",
            path,
        )
    if tilt > 1e-3:
        raise DatasetFormatError(
            f"the laser frame {laser!r} is tilted {math.degrees(tilt):.2f}° (roll/pitch) "
            f"from {base!r}; tilted or upside-down lasers are not supported (give mounting)",
            path,
        )
    return (x, y, yaw), f"{source}: {base} → {laser}"


def _options(options: RosbagOptions | Mapping[str, Any] | None, what: str) -> RosbagOptions:
    if isinstance(options, RosbagOptions):
        return options
    return config_from_mapping(RosbagOptions, options, what)


def read_rosbag(
    path: str | Path,
    options: RosbagOptions | Mapping[str, Any] | None = None,
    *,
    name: str | None = None,
    relations: Relations | None = None,
) -> Dataset:
    """Read a ROS 1 bag, a ROS 2 bag folder, or a ``.db3``/``.mcap`` file into a
    :class:`Dataset` with raw odometry (see the module docstring). ``relations`` become the
    ground truth."""
    opts = _options(options, "rosbag options")
    p = Path(path)
    request = OdometryRequest(
        topic=opts.odom_topic,
        source=opts.odometry_source,
        optional=opts.odom_topic == DEFAULT_ODOM_TOPIC,
        odom_frame=opts.odom_frame.strip("/"),
        base_frame=(opts.base_frame or "base_link").strip("/"),
    )
    bag = read_bag(p, opts.scan_topic, request)
    return _convert(bag, opts, p, name or p.name, relations)


# --------------------------------------------------------------------------------------------
# registry loaders: (options, *, seed, data_root) -> Dataset
# --------------------------------------------------------------------------------------------

_DESCRIPTIONS = {
    "intel-raw": "Intel Research Lab",
    "aces-raw": "ACES building",
    "fr079-raw": "Freiburg building 079",
}


def _freiburg(name: str, options: Mapping[str, Any], data_root: Path | None) -> Dataset:
    """A raw log of the Freiburg benchmark registered as ``name``: its bag (the entry's
    first file) read with ``options`` (the entry's defaults already under them), its
    relations (the second) as the ground truth."""
    from slamkit.datasets.registry import get_dataset_entry

    bag, relations_file = get_dataset_entry(name).files
    root = resolve_data_root(data_root)
    opts = _options(options, name)
    relations = read_relations(require_file(relations_file, root))
    ds = read_rosbag(require_file(bag, root), opts, name=name, relations=relations)
    kept = ds.truth.relations
    summary = (
        f"{_DESCRIPTIONS[name]}, raw log: {ds.metadata['scans']} scans × "
        f"{ds.metadata['beams']} beams, raw odometry, "
        f"{0 if kept is None else len(kept)} reference relations"
        + ("" if opts.max_duration_s is None else f" (first {opts.max_duration_s:g} s)")
    )
    metadata = {**ds.metadata, "relations_file": Path(relations_file).name}
    return replace(ds, description=summary, metadata=metadata)


def load_intel_raw(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """Intel Research Lab raw log (ROS 1 bag): 13,631 scans of 180 beams, raw odometry,
    2984 relations."""
    return _freiburg("intel-raw", options, data_root)


def load_aces_raw(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """ACES building raw log (ROS 1 bag): 7374 scans of 180 beams (50 m), raw odometry,
    1279 relations."""
    return _freiburg("aces-raw", options, data_root)


def load_fr079_raw(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """Freiburg 079 raw log (ROS 1 bag): 4934 scans of 360 beams, raw odometry, laser 4 cm
    behind the robot's centre (:data:`FR079_MOUNTING`), 1685 relations."""
    return _freiburg("fr079-raw", options, data_root)
