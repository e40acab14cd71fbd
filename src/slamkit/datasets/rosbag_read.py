"""The ``rosbags`` side of :mod:`slamkit.datasets.rosbag`: open a bag, check its topics,
deserialise the scan and odometry messages (and the tf tree) into plain arrays.

Every failure of the bag itself (missing, truncated, corrupt, unknown storage, a message that
does not deserialise) becomes a :class:`~slamkit.errors.DatasetFormatError` (a missing file:
:class:`~slamkit.errors.DataNotFoundError`) naming the file; a missing topic or one of
another message type names the topic asked for and lists the topics present with their
types. ``rosbags`` is imported here, on use, so that slamkit without the ``laser`` extra
still imports.

Odometry comes from the odometry topic or, for the many bags that have none, from ``/tf``:
every transform of the odometry frame to the robot's frame over the whole bag (a direct
``odom → base_link`` edge, or ``odom → X`` followed by a fixed chain ``X → … → base_link``
from ``/tf_static``), returned as :class:`OdometryMessages` so that the rest of the reader
treats both sources alike (:class:`OdometryRequest`).
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
from slamkit.datasets.rosbag_records import check_bag1_records, check_mcap_records
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
    "OdometryRequest",
    "ScanMessages",
    "read_bag",
]

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

TF_WINDOW = 10.0
"""How much of ``/tf`` [s from the bag's start] is searched for the laser's mounting."""

TF_TOPIC = "/tf"


@dataclass(frozen=True)
class OdometryRequest:
    """Where to read the robot's odometry from.

    ``source``: ``"topic"``, the ``nav_msgs/Odometry`` topic ``topic`` (None: no odometry;
    ``optional``: a bag without any odometry topic is read as scans only); ``"tf"``, the
    transforms ``odom_frame → base_frame`` on ``/tf``; ``"auto"``, the topic when the bag has
    one, else ``/tf`` when it holds ``odom_frame → base_frame``, else none."""

    topic: str | None
    source: str = "topic"
    optional: bool = False
    odom_frame: str = "odom"
    base_frame: str = "base_link"


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
    """What :func:`read_bag` found: the messages (the odometry from its topic or from
    ``/tf``), the frames, the topics and types present, and the tf edges (child → parent,
    ``/tf_static`` first, then the first :data:`TF_WINDOW` s of ``/tf``)."""

    ros1: bool
    scans: ScanMessages
    odometry: OdometryMessages
    scan_frame: str
    odom_child_frame: str
    topics: dict[str, str]
    edges: dict[str, _Edge] = field(default_factory=dict)
    odometry_topic: str | None = None
    """The odometry topic read (``/tf`` for odometry from the tf tree); None: none (the bag
    has no odometry, or none was asked)."""
    odometry_from: str = ""
    """Where the odometry came from, for people: ``"/odom"``, ``"/tf (odom → base_link)"``;
    empty without odometry."""

    def transform(
        self, base: str, child: str
    ) -> tuple[tuple[float, float, float], float, str] | None:
        """The pose ``(x, y, yaw)`` of frame ``child`` in frame ``base`` chained through the
        tf edges, the largest tilt on the way, and where it came from; None if unlinked."""
        return _chain(self.edges, base, child)


def _chain(
    edges: dict[str, _Edge], base: str, child: str
) -> tuple[tuple[float, float, float], float, str] | None:
    """:meth:`BagContents.transform` over ``edges`` (child → parent)."""
    pose = np.zeros(3)
    tilt = 0.0
    sources: set[str] = set()
    frame = child
    for _ in range(len(edges) + 1):
        if frame == base:
            x, y, yaw = (float(v) for v in pose)
            return (x, y, wrap_angle_float(yaw)), tilt, "+".join(sorted(sources))
        edge = edges.get(frame)
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


def _odometry_plan(
    request: OdometryRequest, topics: dict[str, str], path: Path
) -> tuple[str | None, bool]:
    """The odometry topic to read (None: none) and whether to look for it on ``/tf``."""
    if request.source == "tf":
        if topics.get(TF_TOPIC) != TF_MESSAGE:
            raise DatasetFormatError(
                f"odometry from tf asked, but the bag has no {TF_TOPIC} ({TF_MESSAGE}); it has: "
                f"{_topics_text(topics)}",
                path,
            )
        return None, True
    topic = request.topic
    if request.optional and topic not in topics and ODOMETRY not in topics.values():
        # a bag without an odometry topic: /tf (auto), else the scans alone
        return None, request.source == "auto" and topics.get(TF_TOPIC) == TF_MESSAGE
    return topic, False


_TfRows = dict[str, list[tuple[int, int, int, float, float, float, float, float, float]]]


def _collect_odometry(msg: Any, ts: int, odom_frame: str, rows: _TfRows) -> None:
    """Append every transform of ``msg`` from ``odom_frame`` to ``rows[child]``: stamp, bag
    time, x, y and the quaternion."""
    for tr in msg.transforms:
        if str(tr.header.frame_id).strip("/") != odom_frame:
            continue
        t, r, stamp = tr.transform.translation, tr.transform.rotation, tr.header.stamp
        rows.setdefault(str(tr.child_frame_id).strip("/"), []).append(
            (stamp.sec, stamp.nanosec, ts, t.x, t.y, r.x, r.y, r.z, r.w)
        )


def _read_tf(
    reader: Any, topics: dict[str, str], odom_frame: str | None
) -> tuple[dict[str, _Edge], _TfRows]:
    """The tf edges (``/tf_static``, then the first :data:`TF_WINDOW` s of ``/tf``) and, when
    ``odom_frame`` is given, every transform from it over the whole of ``/tf`` by child."""
    edges: dict[str, _Edge] = {}
    rows: _TfRows = {}
    for topic, window in (("/tf_static", None), (TF_TOPIC, TF_WINDOW)):
        if topics.get(topic) != TF_MESSAGE:
            continue
        conns = [c for c in reader.connections if c.topic == topic]
        stop = None if window is None else reader.start_time + int(window * 1e9)
        odom = odom_frame if topic == TF_TOPIC else None
        for conn, ts, raw in reader.messages(
            connections=conns, stop=stop if odom is None else None
        ):
            msg = reader.deserialize(raw, conn.msgtype)
            if stop is None or ts < stop:
                _add_edges(msg, edges, topic)
            if odom is not None:
                _collect_odometry(msg, ts, odom, rows)
    return edges, rows


def _tf_odometry(
    rows: _TfRows, edges: dict[str, _Edge], request: OdometryRequest, path: Path
) -> tuple[OdometryMessages, str] | None:
    """The transforms ``odom_frame → base_frame`` as odometry messages, and where they came
    from: the direct edge, else ``odom_frame → X`` (on ``/tf``) composed with a chain
    ``X → … → base_frame`` wholly on ``/tf_static``. None (``auto``) or an error (``tf``)
    when there is neither."""
    odom, base = request.odom_frame, request.base_frame
    fixed: tuple[float, float, float] = (0.0, 0.0, 0.0)
    child = base if base in rows else ""
    for candidate in sorted(rows) if not child else ():
        chain = _chain(edges, candidate, base)
        if chain is not None and chain[2] == "/tf_static":
            child, fixed = candidate, chain[0]
            break
    if not child:
        if request.source == "auto":
            return None
        seen = ", ".join(f"{odom} → {c}" for c in sorted(rows)) or "none"
        raise DatasetFormatError(
            f"no transform {odom} → {base} on {TF_TOPIC} (transforms from {odom!r}: {seen}); "
            "set odom_frame/base_frame",
            path,
        )
    a = np.asarray(rows[child], dtype=np.float64).reshape(-1, 9)
    ints = np.asarray([r[:3] for r in rows[child]], dtype=np.int64).reshape(-1, 3)
    position, q = a[:, 3:5].copy(), a[:, 5:9].copy()
    via = f"{odom} → {base}"
    if child != base:  # T_odom_base = T_odom_X ⊕ T_X_base, T_X_base fixed
        qx, qy, qz, qw = q.T
        # heading of the (possibly unnormalised) quaternion: scale cancels in atan2
        yaw = np.arctan2(2.0 * (qw * qz + qx * qy), qw * qw + qx * qx - qy * qy - qz * qz)
        fx, fy, fyaw = fixed
        c, s = np.cos(yaw), np.sin(yaw)
        position = position + np.column_stack([c * fx - s * fy, s * fx + c * fy])
        # q ⊗ q_z(fyaw), q_z = (0, 0, sin(fyaw/2), cos(fyaw/2)) (Hamilton product, x y z w)
        sz, cz = math.sin(fyaw / 2.0), math.cos(fyaw / 2.0)
        q = np.column_stack(
            [qx * cz + qy * sz, qy * cz - qx * sz, qz * cz + qw * sz, qw * cz - qz * sz]
        )
        via = f"{odom} → {child} → {base}"
    messages = OdometryMessages(
        sec=ints[:, 0],
        nsec=ints[:, 1],
        bag_times=_ns_seconds(ints[:, 2]),
        position=position,
        orientation=q,
        speed=np.zeros(len(a)),
    )
    return messages, f"{TF_TOPIC} ({via})"


@dataclass
class _Collected:
    """The scan and odometry messages as read, field by field, before they become arrays."""

    s_int: list[tuple[int, int, int]] = field(default_factory=list)
    s_geo: list[tuple[float, float, float, float, float]] = field(default_factory=list)
    s_ranges: list[NDArray[np.float32]] = field(default_factory=list)
    o_int: list[tuple[int, int, int]] = field(default_factory=list)
    o_pose: list[tuple[float, ...]] = field(default_factory=list)
    scan_frame: str = ""
    odom_child: str = ""

    def add(self, msg: Any, ts: int, is_scan: bool) -> None:
        """One message: a LaserScan (``is_scan``) or an Odometry, recorded at ``ts`` [ns]."""
        stamp = msg.header.stamp
        if is_scan:
            if not self.s_int:
                self.scan_frame = str(msg.header.frame_id)
            self.s_int.append((stamp.sec, stamp.nanosec, ts))
            self.s_geo.append((msg.angle_min, msg.angle_max, msg.angle_increment,
                               msg.range_min, msg.range_max))  # fmt: skip
            self.s_ranges.append(np.asarray(msg.ranges, dtype=np.float32))
            return
        if not self.o_int:
            self.odom_child = str(msg.child_frame_id)
        pos, q = msg.pose.pose.position, msg.pose.pose.orientation
        self.o_int.append((stamp.sec, stamp.nanosec, ts))
        self.o_pose.append((pos.x, pos.y, q.x, q.y, q.z, q.w, msg.twist.twist.linear.x))

    def scans(self) -> ScanMessages:
        si = np.asarray(self.s_int, dtype=np.int64).reshape(-1, 3)
        sg = np.asarray(self.s_geo, dtype=np.float64).reshape(-1, 5)
        return ScanMessages(
            sec=si[:, 0],
            nsec=si[:, 1],
            bag_times=_ns_seconds(si[:, 2]),
            angle_min=sg[:, 0],
            angle_max=sg[:, 1],
            angle_increment=sg[:, 2],
            range_min=sg[:, 3],
            range_max=sg[:, 4],
            beam_counts=np.asarray([r.size for r in self.s_ranges], dtype=np.int64),
            ranges=self.s_ranges,
        )

    def odometry(self) -> OdometryMessages:
        oi = np.asarray(self.o_int, dtype=np.int64).reshape(-1, 3)
        op = np.asarray(self.o_pose, dtype=np.float64).reshape(-1, 7)
        return OdometryMessages(
            sec=oi[:, 0],
            nsec=oi[:, 1],
            bag_times=_ns_seconds(oi[:, 2]),
            position=op[:, :2].copy(),
            orientation=op[:, 2:6].copy(),
            speed=op[:, 6].copy(),
        )


def _read_messages(
    reader: Any, path: Path, scan_topic: str, request: OdometryRequest
) -> BagContents:
    topics = {t: str(info.msgtype) for t, info in reader.topics.items()}
    scan_conns = _connections(reader, scan_topic, LASER_SCAN, topics, path)
    odom_topic, from_tf = _odometry_plan(request, topics, path)
    odom_conns = (
        [] if odom_topic is None else _connections(reader, odom_topic, ODOMETRY, topics, path)
    )
    got = _Collected()
    deserialize = reader.deserialize
    for conn, ts, raw in reader.messages(connections=[*scan_conns, *odom_conns]):
        got.add(deserialize(raw, conn.msgtype), ts, conn.topic == scan_topic)
    edges, tf_rows = _read_tf(reader, topics, request.odom_frame if from_tf else None)
    odometry, odometry_from, odom_child = got.odometry(), odom_topic or "", got.odom_child
    found = _tf_odometry(tf_rows, edges, request, path) if from_tf else None
    if found is not None:
        odometry, odometry_from = found
        odom_topic, odom_child = TF_TOPIC, request.base_frame
    return BagContents(
        ros1=not reader.is2,
        scans=got.scans(),
        odometry=odometry,
        scan_frame=got.scan_frame,
        odom_child_frame=odom_child,
        topics=topics,
        edges=edges,
        odometry_topic=odom_topic,
        odometry_from=odometry_from,
    )


def _ns_seconds(ns: NDArray[np.int64]) -> FloatArray:
    """Nanoseconds → seconds as ``sec + nsec·1e-9`` (as for header stamps)."""
    sec, nsec = np.divmod(ns, 1_000_000_000)
    return sec.astype(np.float64) + nsec.astype(np.float64) * 1e-9


def read_bag(path: Path, scan_topic: str, odometry: OdometryRequest) -> BagContents:
    """Open the bag at ``path`` (ROS 1 ``.bag``; ROS 2 folder, ``.db3`` or ``.mcap``) and
    read the scans, the odometry ``odometry`` asks for (see :class:`OdometryRequest`) and
    the tf tree (see the module docstring)."""
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
        # lz4 reports a damaged compressed chunk as a bare RuntimeError ("LZ4F_decompress
        # failed"); in this block nothing else raises one.
        RuntimeError,
        # An MCAP file carries its own message definitions: a damaged one may lack a field
        # the reader takes (AttributeError) or state an array length no index can hold.
        AttributeError,
        OverflowError,
        # ... and a cut one makes the MCAP reader take an empty byte string for a character.
        TypeError,
    )
    try:
        if path.is_file():
            check_bag1_records(path)  # before rosbags trusts a damaged length
            check_mcap_records(path)
        reader = AnyReader([path], default_typestore=get_typestore(Stores.LATEST))
        with reader:
            return _read_messages(reader, path, scan_topic, odometry)
    except DatasetFormatError:
        raise
    except failures as exc:
        why = str(exc) or type(exc).__name__
        raise DatasetFormatError(
            f"cannot read the bag ({type(exc).__name__}: {why}); expected a ROS 1 .bag, a ROS 2 "
            "bag folder, or a .db3/.mcap file",
            path,
        ) from exc
