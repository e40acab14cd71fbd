"""Small valid inputs of every reader, generated here (CI has no real data), and the call
that reads them. Seeded, so every run fuzzes the same inputs."""

from __future__ import annotations

import gzip
import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
from fuzzcases import QUIRKS, Target

from slamkit.datasets.carmen import read_carmen_log, read_dpslam_log
from slamkit.datasets.carmen_raw import read_carmen_raw_log
from slamkit.datasets.isam_landmarks import CITYTREES_FILES, load_citytrees10000
from slamkit.datasets.mrclam import load_mrclam, mrclam_files
from slamkit.datasets.mrclam_snapshots import (
    GROUNDTRUTH_FILE,
    LANDMARK_FILE,
    MEASUREMENT_FILE,
    load_mrclam_snapshots,
)
from slamkit.datasets.plaza import DR_FILE, GT_FILE, TD_FILE, TL_FILE, load_plaza1
from slamkit.datasets.relations import read_relations
from slamkit.datasets.victoria_park import (
    DETECTIONS_FILE,
    GPS_FILE,
    ODOMETRY_FILE,
    load_victoria_park,
)
from slamkit.io.posegraph import read_graph
from slamkit.io.rosmap_read import RosMapReading, read_ros_map_reading
from slamkit.io.tum import read_tum


def _text(lines: list[str]) -> bytes:
    return ("\n".join(lines) + "\n").encode()


def _gz(lines: list[str]) -> bytes:
    return gzip.compress(_text(lines), mtime=0)


RNG_SEED = 2026
UNIX_T0 = 1018936000.25
"""The first stamp of the laser logs: a Unix time, as real logs have (so that six
significant digits lose the timing, as they do in the field)."""


def _path(n: int = 12) -> np.ndarray:
    """A gentle seeded path (x, y, theta)."""
    rng = np.random.default_rng(RNG_SEED)
    th = np.cumsum(rng.uniform(-0.2, 0.2, n))
    x = np.cumsum(0.5 * np.cos(th))
    y = np.cumsum(0.5 * np.sin(th))
    return np.column_stack([x, y, th])


# ------------------------------------------------------------------------------------ CARMEN
def carmen_target() -> Target:
    poses = _path(6)
    lines = [
        "# message formats defined: PARAM SYNC ODOM FLASER RLASER TRUEPOS",
        "PARAM robot_frontlaser_offset 0.0 nohost 0",
    ]
    for k, (x, y, th) in enumerate(poses):
        r = " ".join(f"{1.0 + 0.01 * i + 0.1 * k:.3f}" for i in range(180))
        t = UNIX_T0 + 0.5 * k
        lines.append(f"ODOM {x:.4f} {y:.4f} {th:.4f} 0 0 0 {t - 0.1:.6f} host {t - 0.1:.6f}")
        lines.append(f"FLASER 180 {r} {x} {y} {th} {x} {y} {th} {t:.6f} host {t:.6f}")
    rel = "log.log.gz"
    return Target(
        "carmen", {rel: _gz(lines)}, lambda root: read_carmen_log(root / rel), quirks=QUIRKS
    )


def dpslam_target() -> Target:
    lines = []
    for k, (x, y, th) in enumerate(_path(6)):
        lines.append(f"Odometry {x:.5f} {y:.5f} {th:.5f}")
        lines.append("Laser 181 " + " ".join(f"{0.5 + 0.01 * i + k * 0.1:.6f}" for i in range(181)))
    rel = "loop.log.gz"
    return Target("dpslam", {rel: _gz(lines)}, lambda root: read_dpslam_log(root / rel))


def carmen_raw_target() -> Target:
    lines = [
        "# a raw log",
        "PARAM laser_front_laser_fov 180",
        "PARAM laser_front_laser_resolution 45",
        "PARAM robot_front_laser_max 20",
    ]
    for k, (x, y, th) in enumerate(_path(5).tolist()):
        t = UNIX_T0 + 0.25 * k
        r = " ".join(repr(1.0 + 0.5 * i + 0.1 * k) for i in range(5))
        lx, ly = x + 0.1 * math.cos(th), y + 0.1 * math.sin(th)
        lines.append(f"ODOM {x!r} {y!r} {th!r} 0.1 0.0 0.0 {t - 0.1!r} myhost {t - 0.09!r}")
        lines.append(
            f"FLASER 5 {r} {lx!r} {ly!r} {th!r} {x!r} {y!r} {th!r} {t!r} myhost {t + 0.01!r}"
        )
    rel = "log.clf"
    return Target(
        "carmen_raw",
        {rel: _text(lines)},
        lambda root: read_carmen_raw_log(root / rel),
        quirks=QUIRKS,
    )


# ------------------------------------------------------------------------------------ MRCLAM
LANDMARK_SUBJECTS = tuple(range(6, 21))


def mrclam_target() -> Target:
    barcodes, landmarks, readings, odometry = mrclam_files(1, 1)
    rng = np.random.default_rng(RNG_SEED)
    bar = ["# Subject #    Barcode #"] + [f"  {s} \t  {10 + 3 * s}" for s in range(1, 21)]
    lms = ["# Subject # x y sx sy"] + [
        f"  {s} \t {rng.uniform(-5, 5):.6f} \t {rng.uniform(-5, 5):.6f} \t 0.0003 \t 0.0004"
        for s in LANDMARK_SUBJECTS
    ]
    t0 = 1248272272.841
    odo = ["# Time v w"] + [f"{t0 + 0.01 * k:.3f} \t  0.074 \t  0.229" for k in range(300)]
    meas = ["# Time subject range bearing"]
    for k in range(12):
        s = LANDMARK_SUBJECTS[k % len(LANDMARK_SUBJECTS)]
        meas.append(f"{t0 + 0.2 + 0.2 * k:.3f} \t  {10 + 3 * s} \t  {2.0 + 0.1 * k:.3f} \t  0.025")
    files = {
        barcodes: _text(bar),
        landmarks: _text(lms),
        readings: _text(meas),
        odometry: _gz(odo),
    }
    return Target("mrclam", files, lambda root: load_mrclam({}, seed=0, data_root=root))


def snapshots_target() -> Target:
    rng = np.random.default_rng(RNG_SEED)
    lms = ["# landmark_id x_m y_m"] + [
        f"{i} {rng.uniform(-5, 5):.6f} {rng.uniform(-5, 5):.6f}" for i in range(1, 8)
    ]
    gt = ["# experiment_id x_m y_m theta_rad"] + [
        f"{e} {x:.6f} {y:.6f} {th:.6f}" for e, (x, y, th) in enumerate(_path(6), start=1)
    ]
    meas = ["# experiment_id landmark_id range_m bearing_rad"]
    for e in range(1, 7):
        for lm in (1 + e % 7, 1 + (e + 3) % 7):
            meas.append(f"{e} {lm} {2.0 + 0.3 * lm:.3f} {0.1 * lm - 0.3:.3f}")
    files = {LANDMARK_FILE: _text(lms), GROUNDTRUTH_FILE: _text(gt), MEASUREMENT_FILE: _text(meas)}
    return Target("mrclam_snapshots", files, lambda root: load_mrclam_snapshots({}, data_root=root))


# ------------------------------------------------------------------------------------- Plaza
def plaza_target() -> Target:
    poses = _path(20)
    t0 = 3856.857346
    dr, td, gt = [], [], ["# time_s x_m y_m heading_rad"]
    beacons = {0: (-46.6, 11.0), 1: (11.0, -6.9), 5: (-17.6, 59.0), 6: (22.0, 23.8)}
    for k, (x, y, th) in enumerate(poses):
        t = t0 + 0.2 * k
        gt.append(f"{t:.6f} {x:.6f} {y:.6f} {th:.6f}")
        if k:
            step = float(np.hypot(*(poses[k, :2] - poses[k - 1, :2])))
            dth = poses[k, 2] - poses[k - 1, 2]
            dr.append(f"  {t:.16e}\t  {step:.16e}\t  {dth:.16e}\t")
        b = (0, 1, 5, 6)[k % 4]
        bx, by = beacons[b]
        td.append(
            f"  {t + 0.01:.16e}\t  2.0e+000\t  {b:.1f}\t  {math.hypot(bx - x, by - y):.10e}\t"
        )
    tl = ["# beacon_id x_m y_m"] + [f"{b} {x} {y}" for b, (x, y) in beacons.items()]
    files = {DR_FILE: _text(dr), TD_FILE: _text(td), GT_FILE: _text(gt), TL_FILE: _text(tl)}
    return Target("plaza", files, lambda root: load_plaza1({}, seed=0, data_root=root))


# ------------------------------------------------------------------------------ Victoria Park
def victoria_park_target() -> Target:
    odo = ["# time_ms speed_m_s steering_rad"] + [
        f"{1000 + 25 * k} {2.0 + 0.01 * k:.3f} {0.1 * math.sin(k / 3):.4f}" for k in range(16)
    ]
    gps = ["# timeGps_ms Lo_m La_m"] + [f"{990 + 50 * k} {5 + 0.1 * k:.2f} 6.0" for k in range(8)]
    det = ["# time_ms range_m bearing_rad x_est y_est feature_index"] + [
        f"{1010 + 30 * k} {4.0 + k:.2f} {0.3 * k % 3.1:.4f} 0 0 {k % 4 - (k == 5)}"
        for k in range(10)
    ]
    files = {ODOMETRY_FILE: _gz(odo), GPS_FILE: _text(gps), DETECTIONS_FILE: _gz(det)}
    return Target(
        "victoria_park", files, lambda root: load_victoria_park({}, seed=0, data_root=root)
    )


# ------------------------------------------------------------------------ iSAM landmark graph
def _isam_lines(noisy: bool) -> list[str]:
    rng = np.random.default_rng(RNG_SEED + int(noisy))
    out = []
    for k in range(10):
        dx, dy, dth = 1.0, 0.0, 0.0
        if noisy:
            dx, dy, dth = dx + 0.01 * rng.normal(), 0.01 * rng.normal(), 0.005 * rng.normal()
        out.append(f"EDGE2 {k} {k + 1} {dx:.6g} {dy:.6g} {dth:.6g} 50 0 0 50 0 100")
        if k % 2:
            lx, ly = -2.5 + 0.01 * rng.normal() * noisy, 2.5
            out.append(f"LANDMARK {k + 1} {11 + k % 3} {lx:.6g} {ly:.6g} 10 0 10")
    return out


def isam_landmarks_target() -> Target:
    files = {
        CITYTREES_FILES[0]: _text(_isam_lines(True)),
        CITYTREES_FILES[1]: _text(_isam_lines(False)),
    }
    return Target(
        "isam_landmarks", files, lambda root: load_citytrees10000({}, seed=0, data_root=root)
    )


# ------------------------------------------------------------------------------ relations, TUM
def relations_target() -> Target:
    rng = np.random.default_rng(RNG_SEED)
    t = 976052896.784509 + np.cumsum(rng.uniform(0.5, 2.0, 10))
    lines = [
        f"{a:.6f} {b:.6f} {rng.normal(0, 0.3):.6f} {rng.normal(0, 0.1):.6f} 0.000000 0.000000 "
        f"0.000000 {rng.normal(0, 1):.6f}"
        for a, b in itertools.pairwise(t)
    ]
    rel = "lab.relations"
    return Target("relations", {rel: _text(lines)}, lambda root: read_relations(root / rel))


def tum_target() -> Target:
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    for k, (x, y, th) in enumerate(_path(10)):
        lines.append(
            f"{10 + 0.1 * k:.4f} {x:.6f} {y:.6f} 0 0 0 "
            f"{math.sin(th / 2):.8f} {math.cos(th / 2):.8f}"
        )
    rel = "traj.tum"
    return Target("tum", {rel: _text(lines)}, lambda root: read_tum(root / rel), check=_tum_check)


def _tum_check(result: tuple[np.ndarray, np.ndarray]) -> list[str]:
    """A trajectory's stamps must increase strictly (poses are paired by stamp)."""
    return [] if np.all(np.diff(result[0]) > 0) else ["TUM stamps not strictly increasing"]


# ---------------------------------------------------------------------------- ROS map_server
def rosmap_target() -> Target:
    """A map_server pair as map_saver writes it: 0 occupied, 254 free, 205 unknown."""
    rng = np.random.default_rng(RNG_SEED)
    img = rng.choice(np.array([0, 205, 254], dtype=np.uint8), size=(6, 9))
    yaml = [
        "image: map.pgm",
        "resolution: 0.050000",
        "origin: [-1.000000, -2.500000, 0.000000]",
        "negate: 0",
        "occupied_thresh: 0.65",
        "free_thresh: 0.196",
    ]
    files = {"map.yaml": _text(yaml), "map.pgm": b"P5\n# CREATOR: test\n9 6\n255\n" + img.tobytes()}
    return Target(
        "rosmap",
        files,
        lambda root: read_ros_map_reading(root / "map.yaml"),
        binary=("map.pgm",),
        check=_rosmap_check,
    )


def _rosmap_check(result: RosMapReading) -> list[str]:
    """Occupancies in [0, 1] (the grid checks it) on a grid of a positive, finite cell."""
    grid = result.grid
    ok = grid.resolution > 0 and np.isfinite(grid.resolution) and grid.prob.size > 0
    return [] if ok else [f"grid: resolution {grid.resolution!r}, shape {grid.shape}"]


# --------------------------------------------------------------------------------- pose graphs
def _graph_target(name: str, rel: str, lines: list[str], family: str) -> Target:
    def run(root: Path) -> Any:
        return read_graph(root / rel, family=family)  # type: ignore[arg-type]

    return Target(name, {rel: _text(lines)}, run)


def g2o_target() -> Target:
    p = _path(6)
    lines = [f"VERTEX_SE2 {i} {x:.6f} {y:.6f} {th:.6f}" for i, (x, y, th) in enumerate(p)]
    lines += [f"EDGE_SE2 {i} {i + 1} 0.5 0.01 0.02 500 0 0 500 0 1000" for i in range(5)]
    lines += ["EDGE_SE2 0 5 2.4 0.3 0.4 50 0 0 50 0 100", "FIX 0"]
    lines += ["VERTEX_XY 100 1.0 2.0", "EDGE_SE2_XY 2 100 0.5 1.5 100 0 100"]
    return _graph_target("g2o", "graph.g2o", lines, "g2o")


def toro_target() -> Target:
    p = _path(6)
    lines = [f"VERTEX2 {i} {x:.6f} {y:.6f} {th:.6f}" for i, (x, y, th) in enumerate(p)]
    # TORO's order: xx xy yy tt xt yt
    lines += [f"EDGE2 {i} {i + 1} 0.5 0.01 0.02 500 0 500 1000 0 0" for i in range(5)]
    lines += ["EDGE2 0 5 2.4 0.3 0.4 50 0 50 100 0 0"]
    return _graph_target("toro", "graph.graph", lines, "toro")


def isam_graph_target() -> Target:
    lines = [f"EDGE2 {i} {i + 1} 0.5 0.01 0.02 50 0 0 50 0 100" for i in range(6)]
    lines += ["EDGE2 0 6 2.9 0.3 0.1 5 0 0 5 0 10", "LANDMARK 3 40 1.0 2.0 10 0 10"]
    return _graph_target("isam", "graph.isam", lines, "isam")


def gtsam_target() -> Target:
    lines = [f"ODOMETRY {i} {i + 1} 0.5 0.01 0.02 0.002 0 0 0.002 0 0.001" for i in range(5)]
    lines += ["ODOMETRY 0 5 2.4 0.3 0.4 0.02 0 0 0.02 0 0.01"]
    return _graph_target("gtsam", "graph_gtsam.txt", lines, "gtsam")


# ------------------------------------------------------------------------------------- rosbag
def rosbag_target(name: str = "rosbag", compression: str = "") -> Target | None:
    """A small ROS 1 bag written with rosbags' writer (its chunks compressed with
    ``compression``); None when rosbags is absent."""
    try:
        import rosbags  # noqa: F401
    except ImportError:
        return None
    from slamkit.datasets.rosbag import read_rosbag

    rel = "small.bag"
    # A quirk of the field: angle_max one increment off (5 beams from -1 by 0.5 end at 1.0).
    off = small_bag(angle_max=1.5, compression=compression)
    return Target(
        name,
        {rel: small_bag(compression=compression)},
        lambda root: read_rosbag(root / rel),
        binary=(rel,),
        quirks={"quirk_angle_max_one_increment_off": lambda rng, data: off},
    )


def small_bag(
    angle_max: float = 1.0,
    compression: str = "",
    mounting: tuple[float, float, float] | None = None,
) -> bytes:
    """Four scans (5 beams from -1 rad by 0.5 rad) and four odometry messages; ``angle_max``
    as written; ``compression`` ``""`` or ``"lz4"`` (the chunks); ``mounting``: a
    ``/tf_static`` transform ``base_link → laser`` (x, y, yaw)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    if "tf2_msgs/msg/TFMessage" not in ts.types:  # not in rosbags' ROS 1 store
        from rosbags.typesys import get_types_from_msg

        ts.register(
            get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
            )
        )
    T = ts.types
    msgs = _small_messages(T, ros1=True, angle_max=angle_max)
    if mounting is not None:  # after the first odometry message, before the first scan
        _, _, scan_ns, scan = msgs[1]
        tf = _tf(T, scan.header.stamp, mounting)
        msgs.insert(1, ("/tf_static", "tf2_msgs/msg/TFMessage", scan_ns - 2000, tf))
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "b.bag"
        w = Writer(path)
        if compression:
            w.set_compression(Writer.CompressionFormat[compression.upper()])
        w.open()
        conns: dict[str, Any] = {}
        for topic, msgtype, _, _ in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=ts)
        for topic, msgtype, stamp_ns, msg in msgs:
            w.write(conns[topic], stamp_ns, ts.serialize_ros1(msg, msgtype))
        w.close()
        return path.read_bytes()


def mcap_target() -> Target | None:
    """A small ROS 2 bag in MCAP storage (the file alone, as a user hands it over); None
    when rosbags is absent."""
    try:
        import rosbags  # noqa: F401
    except ImportError:
        return None
    from slamkit.datasets.rosbag import read_rosbag

    rel = "small.mcap"
    off = small_mcap(angle_max=1.5)  # the quirk: angle_max one increment off
    return Target(
        "mcap",
        {rel: small_mcap()},
        lambda root: read_rosbag(root / rel),
        binary=(rel,),
        quirks={"quirk_angle_max_one_increment_off": lambda rng, data: off},
    )


def small_mcap(angle_max: float = 1.0) -> bytes:
    """:func:`small_bag`'s four scans and four odometry messages as ROS 2 messages (no
    ``seq`` in the header) in an MCAP file; ``angle_max`` as written."""
    import tempfile

    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    msgs = _small_messages(ts.types, ros1=False, angle_max=angle_max)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "bag"
        w = Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP)
        w.open()
        conns: dict[str, Any] = {}
        for topic, msgtype, _, _ in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=ts)
        for topic, msgtype, stamp_ns, msg in msgs:
            w.write(conns[topic], stamp_ns, ts.serialize_cdr(msg, msgtype))
        w.close()
        (storage,) = folder.glob("*.mcap")
        return storage.read_bytes()


def _small_messages(T: Any, ros1: bool, angle_max: float) -> list[tuple[str, str, int, Any]]:
    """The four odometry messages and four scans (5 beams from -1 rad by 0.5 rad, ranges
    1-5 m plus the scan's index) of :func:`small_bag` and :func:`small_mcap` as ``(topic,
    type, bag stamp [ns], message)`` in bag order, with the types ``T`` of a ROS 1 or a
    ROS 2 store (a ROS 1 header has a ``seq``)."""
    Vec, Quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]

    def header(k: int, stamp: Any, frame: str) -> Any:
        if ros1:
            return T["std_msgs/msg/Header"](seq=k, stamp=stamp, frame_id=frame)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    msgs = []
    for k, (x, y, th) in enumerate(_path(4)):
        ns = 1_000_000_000 + 100_000_000 * k
        stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        scan = T["sensor_msgs/msg/LaserScan"](
            header=header(k, stamp, "laser"),
            angle_min=-1.0, angle_max=angle_max, angle_increment=0.5, time_increment=0.0,
            scan_time=0.0, range_min=0.1, range_max=10.0,
            ranges=np.array([1.0, 2.0, 3.0, 4.0, 5.0], dtype=np.float32) + k,
            intensities=np.zeros(0, dtype=np.float32),
        )  # fmt: skip
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
            orientation=Quat(x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2)),
        )
        odom = T["nav_msgs/msg/Odometry"](
            header=header(k, stamp, "odom"),
            child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=Vec(x=0.0, y=0.0, z=0.0),
                                                   angular=Vec(x=0.0, y=0.0, z=0.0)),
                covariance=np.zeros(36),
            ),
        )  # fmt: skip
        msgs.append(("/odom", "nav_msgs/msg/Odometry", ns - 1000, odom))
        msgs.append(("/scan", "sensor_msgs/msg/LaserScan", ns, scan))
    return msgs


def _tf(T: Any, stamp: Any, pose: tuple[float, float, float]) -> Any:
    """A ``TFMessage`` with one transform ``base_link → laser`` at ``pose``."""
    x, y, yaw = pose
    Vec, Quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    tr = T["geometry_msgs/msg/TransformStamped"](
        header=T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="base_link"),
        child_frame_id="laser",
        transform=T["geometry_msgs/msg/Transform"](
            translation=Vec(x=x, y=y, z=0.0),
            rotation=Quat(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)),
        ),
    )
    return T["tf2_msgs/msg/TFMessage"](transforms=[tr])


def all_targets() -> list[Target]:
    out = [
        carmen_target(),
        carmen_raw_target(),
        dpslam_target(),
        mrclam_target(),
        snapshots_target(),
        plaza_target(),
        victoria_park_target(),
        isam_landmarks_target(),
        relations_target(),
        g2o_target(),
        toro_target(),
        isam_graph_target(),
        gtsam_target(),
        tum_target(),
        rosmap_target(),
    ]
    for bag in (rosbag_target(), rosbag_target("rosbag_lz4", "lz4"), mcap_target()):
        if bag is not None:
            out.append(bag)
    return out
