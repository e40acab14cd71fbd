"""Fixtures of the data-set tests: small ROS bags written with rosbags' own writers."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest


@dataclass
class ScanSpec:
    """One LaserScan message: stamp [ns], ranges, and its geometry."""

    stamp_ns: int
    ranges: Sequence[float]
    bag_ns: int | None = None  # when recorded; None: the stamp
    angle_min: float = -1.0
    angle_increment: float = 0.5
    angle_max: float | None = None  # None: angle_min + (n - 1) increment
    range_min: float = 0.1
    range_max: float = 10.0
    frame_id: str = "laser"


@dataclass
class OdomSpec:
    """One Odometry message: stamp [ns] and pose (x, y, yaw)."""

    stamp_ns: int
    pose: tuple[float, float, float]
    bag_ns: int | None = None  # when recorded; None: the stamp
    quaternion: tuple[float, float, float, float] | None = None  # x y z w; None: from yaw
    speed: float = 0.0  # the twist's linear.x [m/s]


@dataclass
class BagSpec:
    """What a test bag holds."""

    scans: list[ScanSpec]
    odometry: list[OdomSpec]
    tf_static: list[tuple[str, str, tuple[float, float, float]]] = field(default_factory=list)
    # /tf: one message per entry, (stamp [ns], parent, child, (x, y, yaw))
    tf: list[tuple[int, str, str, tuple[float, float, float]]] = field(default_factory=list)
    scan_topic: str = "/scan"
    odom_topic: str = "/odom"


def _messages(ts: Any, spec: BagSpec, ros1: bool) -> list[tuple[str, str, int, Any]]:
    T = ts.types
    Time = T["builtin_interfaces/msg/Time"]
    Header = T["std_msgs/msg/Header"]

    def header(ns: int, frame: str) -> Any:
        stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        return Header(seq=0, stamp=stamp, frame_id=frame) if ros1 else Header(stamp, frame)

    out: list[tuple[str, str, int, Any]] = []
    for s in spec.scans:
        n = len(s.ranges)
        amax = s.angle_max if s.angle_max is not None else s.angle_min + (n - 1) * s.angle_increment
        msg = T["sensor_msgs/msg/LaserScan"](
            header=header(s.stamp_ns, s.frame_id),
            angle_min=s.angle_min,
            angle_max=amax,
            angle_increment=s.angle_increment,
            time_increment=0.0,
            scan_time=0.0,
            range_min=s.range_min,
            range_max=s.range_max,
            ranges=np.asarray(s.ranges, dtype=np.float32),
            intensities=np.zeros(0, dtype=np.float32),
        )
        bag_ns = s.stamp_ns if s.bag_ns is None else s.bag_ns
        out.append((spec.scan_topic, "sensor_msgs/msg/LaserScan", bag_ns, msg))
    Vec, Quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    for o in spec.odometry:
        x, y, yaw = o.pose
        q = o.quaternion or (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0), orientation=Quat(*q)
        )
        twist = T["geometry_msgs/msg/Twist"](
            linear=Vec(o.speed, 0.0, 0.0), angular=Vec(0.0, 0.0, 0.0)
        )
        msg = T["nav_msgs/msg/Odometry"](
            header=header(o.stamp_ns, "odom"),
            child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
        )
        bag_ns = o.stamp_ns if o.bag_ns is None else o.bag_ns
        out.append((spec.odom_topic, "nav_msgs/msg/Odometry", bag_ns, msg))

    def transform(ns: int, parent: str, child: str, pose: tuple[float, float, float]) -> Any:
        x, y, yaw = pose
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(ns, parent),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=Vec(x, y, 0.0),
                rotation=Quat(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)),
            ),
        )

    if spec.tf_static:
        ns0 = spec.scans[0].stamp_ns
        transforms = [transform(ns0, parent, child, p) for parent, child, p in spec.tf_static]
        tf = T["tf2_msgs/msg/TFMessage"](transforms=transforms)
        out.append(("/tf_static", "tf2_msgs/msg/TFMessage", ns0, tf))
    for ns, parent, child, p in spec.tf:
        tf = T["tf2_msgs/msg/TFMessage"](transforms=[transform(ns, parent, child, p)])
        out.append(("/tf", "tf2_msgs/msg/TFMessage", ns, tf))
    return sorted(out, key=lambda m: m[2])


def write_bag(path: Path, spec: BagSpec, kind: str = "ros1") -> Path:
    """Write ``spec`` as a ROS 1 bag (``kind="ros1"``), a ROS 2 bag folder with SQLite
    (``"ros2"``) or MCAP storage (``"mcap"``); the path to read (the folder for ROS 2)."""
    pytest.importorskip("rosbags", reason="the laser extra (rosbags) is not installed")
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in ts.types:  # not in rosbags' ROS 1 store
        from rosbags.typesys import get_types_from_msg

        ts.register(
            get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
            )
        )
    messages = _messages(ts, spec, ros1)
    if ros1:
        w1 = Writer1(path)
        w1.open()
        conns: dict[str, Any] = {}
        for topic, msgtype, _, _ in messages:
            if topic not in conns:
                conns[topic] = w1.add_connection(topic, msgtype, typestore=ts)
        for topic, msgtype, stamp, msg in messages:
            w1.write(conns[topic], stamp, ts.serialize_ros1(msg, msgtype))
        w1.close()
        return path
    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    w2 = Writer2(path, version=9, storage_plugin=plugin)
    w2.open()
    conns = {}
    for topic, msgtype, _, _ in messages:
        if topic not in conns:
            conns[topic] = w2.add_connection(topic, msgtype, typestore=ts)
    for topic, msgtype, stamp, msg in messages:
        w2.write(conns[topic], stamp, ts.serialize_cdr(msg, msgtype))
    w2.close()
    return path


@pytest.fixture
def bags() -> SimpleNamespace:
    """The test-bag kit: ``Scan``, ``Odom``, ``Bag`` (the specs) and ``write(path, spec,
    kind="ros1")`` (see :func:`write_bag`)."""
    return SimpleNamespace(Scan=ScanSpec, Odom=OdomSpec, Bag=BagSpec, write=write_bag)
