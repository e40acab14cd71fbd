"""The ``rosbags`` side of :mod:`slamkit.datasets.rosbag`: open a bag, check its topics,
deserialise the scan and odometry messages (and the tf tree) into plain arrays.

Every failure of the bag itself (missing, truncated, corrupt, unknown storage, a message that
does not deserialise) becomes a :class:`~slamkit.errors.DatasetFormatError` (a missing file:
:class:`~slamkit.errors.DataNotFoundError`) naming the file; a missing topic or one of
another message type names the topic asked for and lists the topics present with their
types. ``rosbags`` is imported here, on use, so that slamkit without the ``laser`` extra
still imports.
"""

from __future__ import annotations

import math
import sqlite3
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.errors import DataNotFoundError, DatasetFormatError, InputError
from slamkit.geometry.angles import wrap_angle_float
from slamkit.geometry.pose2 import compose

__all__ = [
    "LASER_SCAN",
    "ODOMETRY",
    "TF_MESSAGE",
    "TF_WINDOW",
    "BagContents",
    "OdometryMessages",
    "ScanMessages",
    "read_bag",
]

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

TF_WINDOW = 10.0
"""How much of ``/tf`` [s from the bag's start] is searched for the laser's mounting."""


@dataclass(frozen=True, eq=False)
class ScanMessages:
    """The LaserScan messages of one topic in bag order, field by field: stamps
    ``sec``/``nsec (N,)``, ``bag_times (N,)`` [s] (when recorded), the geometry ``(N,)``
    and the ranges of each (float32 as stored; counts may differ)."""

    sec: NDArray[np.int64]
    nsec: NDArray[np.int64]
    bag_times: FloatArray
    angle_min: FloatArray
    angle_max: FloatArray
    angle_increment: FloatArray
    range_min: FloatArray
    range_max: FloatArray
    beam_counts: NDArray[np.int64]
    ranges: list[NDArray[np.float32]]


@dataclass(frozen=True, eq=False)
class OdometryMessages:
    """The Odometry messages of one topic in bag order: stamps, ``position (M, 2)`` (x, y)
    and ``orientation (M, 4)`` (x, y, z, w) of the pose, and ``speed (M,)``, the twist's
    forward velocity ``linear.x`` [m/s] (0 in bags that do not fill the twist in)."""

    sec: NDArray[np.int64]
    nsec: NDArray[np.int64]
    bag_times: FloatArray
    position: FloatArray
    orientation: FloatArray
    speed: FloatArray


@dataclass(frozen=True)
class _Edge:
    parent: str
    pose: tuple[float, float, float]  # child in parent: x, y, yaw
    tilt: float  # rotation away from the plane [rad]
    source: str


@dataclass(frozen=True, eq=False)
class BagContents:
    """What :func:`read_bag` found: the messages, the frames, the topics and types present,
    and the tf edges (child → parent, ``/tf_static`` first, then the first
    :data:`TF_WINDOW` s of ``/tf``)."""

    ros1: bool
    scans: ScanMessages
    odometry: OdometryMessages
    scan_frame: str
    odom_child_frame: str
    topics: dict[str, str]
    edges: dict[str, _Edge] = field(default_factory=dict)
    odometry_topic: str | None = None
    """The odometry topic read; None: none (the bag has no odometry, or none was asked)."""

    def transform(
        self, base: str, child: str
    ) -> tuple[tuple[float, float, float], float, str] | None:
        """The pose ``(x, y, yaw)`` of frame ``child`` in frame ``base`` chained through the
        tf edges, the largest tilt on the way, and where it came from; None if unlinked."""
        pose = np.zeros(3)
        tilt = 0.0
        sources: set[str] = set()
        frame = child
        for _ in range(len(self.edges) + 1):
            if frame == base:
                x, y, yaw = (float(v) for v in pose)
                return (x, y, wrap_angle_float(yaw)), tilt, "+".join(sorted(sources))
            edge = self.edges.get(frame)
            if edge is None:
                return None
            pose = compose(np.asarray(edge.pose), pose)
            tilt = max(tilt, edge.tilt)
            sources.add(edge.source)
            frame = edge.parent
        return None  # a loop in the tree


def _topics_text(topics: dict[str, str]) -> str:
    return ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "(none)"


def _connections(reader: Any, topic: str, msgtype: str, topics: dict[str, str], path: Path) -> Any:
    if topic not in topics:
        raise DatasetFormatError(
            f"no topic {topic!r} in the bag; it has: {_topics_text(topics)}", path
        )
    if topics[topic] != msgtype:
        raise DatasetFormatError(
            f"topic {topic!r} holds {topics[topic]}, expected {msgtype}; the bag has: "
            f"{_topics_text(topics)}",
            path,
        )
    return [c for c in reader.connections if c.topic == topic]


def _tilt(qx: float, qy: float, qz: float, qw: float) -> tuple[float, float]:
    """``(yaw, tilt)`` of a quaternion: its heading, and how far its rotation axis leaves
    the plane's normal (the angle of the rotation that remains after the yaw)."""
    norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) or 1.0
    qx, qy, qz, qw = qx / norm, qy / norm, qz / norm, qw / norm
    yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    tilt = 2.0 * math.asin(min(1.0, math.sqrt(qx * qx + qy * qy)))
    return yaw, tilt


def _add_edges(msg: Any, edges: dict[str, _Edge], source: str) -> None:
    for tr in msg.transforms:
        child = str(tr.child_frame_id).strip("/")
        if child in edges:
            continue
        t, r = tr.transform.translation, tr.transform.rotation
        yaw, tilt = _tilt(float(r.x), float(r.y), float(r.z), float(r.w))
        parent = str(tr.header.frame_id).strip("/")
        edges[child] = _Edge(parent, (float(t.x), float(t.y), yaw), tilt, source)


def _read_messages(
    reader: Any, path: Path, scan_topic: str, odom_topic: str | None, odom_optional: bool
) -> BagContents:
    topics = {t: str(info.msgtype) for t, info in reader.topics.items()}
    scan_conns = _connections(reader, scan_topic, LASER_SCAN, topics, path)
    if odom_optional and odom_topic not in topics and ODOMETRY not in topics.values():
        odom_topic = None  # a bag without odometry: the scans alone
    odom_conns = (
        [] if odom_topic is None else _connections(reader, odom_topic, ODOMETRY, topics, path)
    )
    s_int: list[tuple[int, int, int]] = []
    s_geo: list[tuple[float, float, float, float, float]] = []
    s_ranges: list[NDArray[np.float32]] = []
    o_int: list[tuple[int, int, int]] = []
    o_pose: list[tuple[float, float, float, float, float, float, float]] = []
    scan_frame = odom_child = ""
    deserialize = reader.deserialize
    for conn, ts, raw in reader.messages(connections=[*scan_conns, *odom_conns]):
        msg = deserialize(raw, conn.msgtype)
        stamp = msg.header.stamp
        if conn.topic == scan_topic:
            if not s_int:
                scan_frame = str(msg.header.frame_id)
            s_int.append((stamp.sec, stamp.nanosec, ts))
            s_geo.append((msg.angle_min, msg.angle_max, msg.angle_increment,
                          msg.range_min, msg.range_max))  # fmt: skip
            s_ranges.append(np.asarray(msg.ranges, dtype=np.float32))
        else:
            if not o_int:
                odom_child = str(msg.child_frame_id)
            pos, q = msg.pose.pose.position, msg.pose.pose.orientation
            o_int.append((stamp.sec, stamp.nanosec, ts))
            o_pose.append((pos.x, pos.y, q.x, q.y, q.z, q.w, msg.twist.twist.linear.x))
    edges: dict[str, _Edge] = {}
    for topic, window in (("/tf_static", None), ("/tf", TF_WINDOW)):
        if topics.get(topic) != TF_MESSAGE:
            continue
        conns = [c for c in reader.connections if c.topic == topic]
        stop = None if window is None else reader.start_time + int(window * 1e9)
        for conn, _, raw in reader.messages(connections=conns, stop=stop):
            _add_edges(deserialize(raw, conn.msgtype), edges, topic)
    si = np.asarray(s_int, dtype=np.int64).reshape(-1, 3)
    sg = np.asarray(s_geo, dtype=np.float64).reshape(-1, 5)
    oi = np.asarray(o_int, dtype=np.int64).reshape(-1, 3)
    op = np.asarray(o_pose, dtype=np.float64).reshape(-1, 7)
    scans = ScanMessages(
        sec=si[:, 0],
        nsec=si[:, 1],
        bag_times=_ns_seconds(si[:, 2]),
        angle_min=sg[:, 0],
        angle_max=sg[:, 1],
        angle_increment=sg[:, 2],
        range_min=sg[:, 3],
        range_max=sg[:, 4],
        beam_counts=np.asarray([r.size for r in s_ranges], dtype=np.int64),
        ranges=s_ranges,
    )
    odometry = OdometryMessages(
        sec=oi[:, 0],
        nsec=oi[:, 1],
        bag_times=_ns_seconds(oi[:, 2]),
        position=op[:, :2].copy(),
        orientation=op[:, 2:6].copy(),
        speed=op[:, 6].copy(),
    )
    return BagContents(
        ros1=not reader.is2,
        scans=scans,
        odometry=odometry,
        scan_frame=scan_frame,
        odom_child_frame=odom_child,
        topics=topics,
        edges=edges,
        odometry_topic=odom_topic,
    )


def _ns_seconds(ns: NDArray[np.int64]) -> FloatArray:
    """Nanoseconds → seconds as ``sec + nsec·1e-9`` (as for header stamps)."""
    sec, nsec = np.divmod(ns, 1_000_000_000)
    return sec.astype(np.float64) + nsec.astype(np.float64) * 1e-9


def read_bag(
    path: Path, scan_topic: str, odom_topic: str | None, odom_optional: bool = False
) -> BagContents:
    """Open the bag at ``path`` (ROS 1 ``.bag``; ROS 2 folder, ``.db3`` or ``.mcap``) and
    read the two topics and the tf tree (see the module docstring); ``odom_topic=None``:
    the scans only; ``odom_optional``: a bag with no odometry topic at all is read as
    scans only rather than refused."""
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.rosbag1 import ReaderError as Reader1Error
        from rosbags.rosbag2 import ReaderError as Reader2Error
        from rosbags.serde import SerdeError
        from rosbags.typesys import Stores, TypesysError, get_typestore
    except ImportError as exc:  # pragma: no cover - the laser extra is installed in CI
        raise InputError(
            "reading ROS bags needs the rosbags package: pip install 'slamkit[laser]'"
        ) from exc
    if not path.exists():
        raise DataNotFoundError(f"{path}: not found")
    failures = (
        AnyReaderError,
        Reader1Error,
        Reader2Error,
        SerdeError,
        TypesysError,
        OSError,
        EOFError,
        struct.error,
        sqlite3.Error,
        ValueError,
        KeyError,
        IndexError,
        AssertionError,
    )
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.LATEST))
        with reader:
            return _read_messages(reader, path, scan_topic, odom_topic, odom_optional)
    except DatasetFormatError:
        raise
    except failures as exc:
        why = str(exc) or type(exc).__name__
        raise DatasetFormatError(
            f"cannot read the bag ({type(exc).__name__}: {why}); expected a ROS 1 .bag, a ROS 2 "
            "bag folder, or a .db3/.mcap file",
            path,
        ) from exc
