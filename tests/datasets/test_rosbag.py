"""ROS bags → Dataset: small ROS 1 / ROS 2 / MCAP bags written here with rosbags' writers
(known scans, odometry, tf) read back exactly; every typed error; the three Freiburg bags."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from slamkit.datasets import LaserScan, Odometry, load_dataset
from slamkit.datasets.raw_odometry import RAW_ODOMETRY_SIGMA_ROT_DEG, RAW_ODOMETRY_SIGMA_TRANS
from slamkit.datasets.registry import DATASETS
from slamkit.datasets.rosbag import RosbagOptions, read_rosbag
from slamkit.errors import ConfigError, DataNotFoundError, DatasetFormatError
from slamkit.geometry import wrap_angle
from slamkit.geometry.pose2 import between

pytest.importorskip("rosbags", reason="the laser extra (rosbags) is not installed")

S = 1_000_000_000  # ns per s
F32 = np.float32

RANGES = [
    [1.0, 2.5, math.inf, 12.0, 0.05],  # +inf and >= range_max: far; 0.05 < range_min: near
    [10.0, -math.inf, 3.25, 0.1, 9.5],  # == range_max: far; -inf: near (REP 117)
    [4.0, 4.0, 4.0, 4.0, 4.0],
    [0.5, 1.5, 2.5, 3.5, 4.5],
]
# What the reader must return: no returns as exactly max_range (10 m), the rest as float32.
EXPECTED = np.array(
    [
        [1.0, 2.5, 10.0, 10.0, 10.0],
        [10.0, 10.0, 3.25, float(F32(0.1)), 9.5],
        [4.0] * 5,
        [0.5, 1.5, 2.5, 3.5, 4.5],
    ]
)
SCAN_NS = [10 * S, 10 * S + S // 10, 10 * S + 2 * S // 10, 10 * S + 3 * S // 10]
ODOM_T = [9.95 + 0.1 * k for k in range(5)]


def _odom_pose(k: int) -> tuple[float, float, float]:
    # headings 3.0 .. 3.8 rad: they cross +pi, so the interpolation must wrap
    return (0.2 * k, -0.1 * k, float(wrap_angle(3.0 + 0.2 * k)))


def _spec(bags: SimpleNamespace, **changes: object) -> object:
    scans = [bags.Scan(ns, r) for ns, r in zip(SCAN_NS, RANGES, strict=True)]
    odometry = [bags.Odom(round(t * S), _odom_pose(k)) for k, t in enumerate(ODOM_T)]
    spec = bags.Bag(scans, odometry, tf_static=[("base_link", "laser", (0.04, 0.02, 0.1))])
    for key, value in changes.items():
        setattr(spec, key, value)
    return spec


def _padded(bags: SimpleNamespace, spec: Any, scans: int = 16, odometry: int = 16) -> Any:
    """``spec`` with ``scans`` more good scans every 0.1 s from 10.4 s and ``odometry`` more
    odometry messages every 0.1 s from 10.45 s: a lenient read that drops one or two of the
    first four scans still keeps 90% of the bag (``reading.MAX_DROPPED_SHARE``)."""
    after = range(1, max(scans, odometry) + 1)
    extra_scans = [bags.Scan(SCAN_NS[-1] + k * S // 10, [4.0] * 5) for k in after]
    extra_odom = [bags.Odom(round((ODOM_T[-1] + 0.1 * k) * S), _odom_pose(4 + k)) for k in after]
    spec.scans = [*spec.scans, *extra_scans[:scans]]
    spec.odometry = [*spec.odometry, *extra_odom[:odometry]]
    return spec


def _write(bags: SimpleNamespace, tmp_path: Path, spec: object, kind: str = "ros1") -> Path:
    return bags.write(tmp_path / ("t.bag" if kind == "ros1" else f"t_{kind}"), spec, kind)


def _scans(ds):
    return [e for e in ds.events if isinstance(e, LaserScan)]


def _odometry(ds):
    return [e for e in ds.events if isinstance(e, Odometry)]


# ------------------------------------------------------------------------ exact round trips
def _check_standard(ds) -> None:
    scans, odom = _scans(ds), _odometry(ds)
    assert len(scans) == len(odom) == 4
    times = np.array([e.t for e in scans])
    # sec + nanosec·1e-9 in float64 is the decimal stamp exactly
    assert times.tolist() == [10.0, 10.1, 10.2, 10.3]
    # one Odometry event just before each scan, at its stamp
    assert [type(e).__name__ for e in ds.events[:2]] == ["Odometry", "LaserScan"]
    assert [e.t for e in odom] == times.tolist()
    np.testing.assert_array_equal(np.array([e.ranges for e in scans]), EXPECTED)
    np.testing.assert_array_equal(ds.laser.beam_angles, [-1.0, -0.5, 0.0, 0.5, 1.0])
    assert ds.laser.max_range == 10.0
    # scan j is halfway between odometry messages j and j+1 (9.95 + 0.1 j, 10.05 + 0.1 j)
    expected = np.array(
        [[0.2 * j + 0.1, -0.1 * j - 0.05, wrap_angle(3.1 + 0.2 * j)] for j in range(4)]
    )
    got = np.array([e.pose for e in odom])
    np.testing.assert_allclose(got[:, :2], expected[:, :2], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(got[:, 2] - expected[:, 2]), 0.0, atol=1e-12)
    assert got[2, 2] == pytest.approx(3.5 - 2 * math.pi, abs=1e-12)  # past +pi: wrapped
    np.testing.assert_allclose(ds.laser.mounting, (0.04, 0.02, 0.1), atol=1e-12)
    np.testing.assert_array_equal(ds.initial_pose, got[0])
    sr = math.radians(RAW_ODOMETRY_SIGMA_ROT_DEG)  # the nominal per-step noise, unscaled
    np.testing.assert_allclose(
        ds.motion.noise_cov, np.diag([sr**2, RAW_ODOMETRY_SIGMA_TRANS**2, sr**2]), rtol=1e-15
    )
    assert ds.motion.source == "odometry"
    md = ds.metadata
    assert md["readings"] == {"no_return_far": 3, "no_return_near": 2, "invalid_readings": 0}
    assert md["dropped"] == {"before_odometry": 0, "after_odometry": 0, "odometry_gap": 0}
    assert md["scan_messages"] == 4 and md["odometry_messages"] == 5
    assert md["mounting_from"] == "/tf_static: base_link → laser"


def test_ros1_bag_reads_back_exact_scans_stamps_and_interpolated_odometry(bags, tmp_path):
    ds = read_rosbag(_write(bags, tmp_path, _spec(bags)))
    _check_standard(ds)
    assert ds.metadata["format"] == "rosbag1" and ds.name == "t.bag"


@pytest.mark.parametrize("kind", ["ros2", "mcap"])
def test_ros2_folder_sqlite_and_mcap_read_the_same(bags, tmp_path, kind):
    folder = _write(bags, tmp_path, _spec(bags), kind)
    ds = read_rosbag(folder)
    _check_standard(ds)
    assert ds.metadata["format"] == "rosbag2"
    # one storage file on its own (no metadata.yaml): rosbags 0.11 reads .db3 and .mcap
    (storage,) = folder.glob("*.mcap" if kind == "mcap" else "*.db3")
    alone = tmp_path / f"alone{storage.suffix}"
    alone.write_bytes(storage.read_bytes())
    ds2 = read_rosbag(alone)
    _check_standard(ds2)
    assert ds2.metadata["format"] == ("mcap" if kind == "mcap" else "rosbag2")


def test_odometry_gap_within_the_limit_interpolates_across_it(bags, tmp_path):
    odometry = [bags.Odom(round(t * S), _odom_pose(k)) for k, t in enumerate(ODOM_T)]
    spec = _spec(bags, odometry=[odometry[0], odometry[1], odometry[4]])  # 10.05 .. 10.35
    ds = read_rosbag(_write(bags, tmp_path, spec))  # gap 0.3 s < 0.5 s
    pose = _odometry(ds)[2].pose  # t = 10.2: half way from 10.05 to 10.35
    np.testing.assert_allclose(pose[:2], [0.2 * 2.5, -0.1 * 2.5], atol=1e-12)
    assert float(wrap_angle(pose[2] - (3.0 + 0.2 * 2.5))) == pytest.approx(0.0, abs=1e-12)


def test_odometry_direction_twist_reverses_the_steps_the_speed_says_went_backward(bags, tmp_path):
    # Poses that always advance along x (heading 0.3 rad), as if integrated from the
    # unsigned speed, while the twist says messages 1 -> 3 reversed.
    yaw = 0.3
    step = 0.1 * np.array([math.cos(yaw), math.sin(yaw)])
    speeds = [0.5, -0.5, -0.5, -0.5, 0.5]
    odometry = [
        bags.Odom(round(t * S), (k * step[0], k * step[1], yaw), speed=v)
        for k, (t, v) in enumerate(zip(ODOM_T, speeds, strict=True))
    ]
    path = _write(bags, tmp_path, _spec(bags, odometry=odometry))
    as_poses = np.array([e.pose for e in _odometry(read_rosbag(path))])
    signed = read_rosbag(path, options={"odometry_direction": "twist"})
    by_twist = np.array([e.pose for e in _odometry(signed)])
    # Steps 0->1 (speeds 0.5, -0.5: sum 0, kept) and 3->4 (sum 0, kept) go forward; steps
    # 1->2 and 2->3 go backward: the poses at messages 0..4 are at 0, 1, 0, -1, 0 steps.
    along = np.array([0.0, 1.0, 0.0, -1.0, 0.0])
    # Scans at 10.0, 10.1, 10.2, 10.3 s: halfway between messages 0-1, 1-2, 2-3, 3-4.
    expected = 0.5 * (along[:-1] + along[1:])[:, None] * step
    np.testing.assert_allclose(by_twist[:, :2], expected, atol=1e-12)
    np.testing.assert_allclose(by_twist[:, 2], as_poses[:, 2], atol=1e-15)  # headings kept
    np.testing.assert_allclose(as_poses[:, :2], (np.arange(4) + 0.5)[:, None] * step, atol=1e-12)
    assert signed.provenance.options["odometry_direction"] == "twist"


def test_mounting_chains_static_transforms_and_can_be_given(bags, tmp_path):
    tf = [("base_link", "mount", (0.1, 0.0, math.pi / 2)), ("mount", "laser", (0.2, 0.0, 0.0))]
    path = _write(bags, tmp_path, _spec(bags, tf_static=tf))
    np.testing.assert_allclose(
        read_rosbag(path).laser.mounting, (0.1, 0.2, math.pi / 2), atol=1e-12
    )
    given = read_rosbag(path, {"mounting": [0.5, 0.0, 0.0]})
    assert given.laser.mounting == (0.5, 0.0, 0.0)
    assert given.metadata["mounting_from"] == "option mounting"


def test_no_tf_puts_the_laser_at_the_robot_origin(bags, tmp_path):
    ds = read_rosbag(_write(bags, tmp_path, _spec(bags, tf_static=[])))
    assert ds.laser.mounting == (0.0, 0.0, 0.0)
    assert "no tf" in ds.metadata["mounting_from"]


def test_bag_stamps_option_uses_the_recording_times(bags, tmp_path):
    scans = [bags.Scan(ns, r, bag_ns=ns + S // 100) for ns, r in zip(SCAN_NS, RANGES, strict=True)]
    ds = read_rosbag(_write(bags, tmp_path, _spec(bags, scans=scans)), {"stamps": "bag"})
    np.testing.assert_allclose([e.t for e in _scans(ds)], [10.01, 10.11, 10.21, 10.31], atol=1e-12)


def test_scans_outside_the_odometry_are_dropped_and_counted(bags, tmp_path):
    odometry = [bags.Odom(round(t * S), _odom_pose(k)) for k, t in enumerate(ODOM_T)]
    # odometry 10.05 .. 11.85 s, scans 10.0 .. 11.9 s: the first and the last have none
    spec = _padded(bags, _spec(bags, odometry=odometry[1:4]), scans=16, odometry=15)
    ds = read_rosbag(_write(bags, tmp_path, spec))
    times = [e.t for e in _scans(ds)]
    assert len(times) == 18 and times[:3] == [10.1, 10.2, 10.3] and times[-1] == 11.8
    assert ds.metadata["dropped"] == {"before_odometry": 1, "after_odometry": 1, "odometry_gap": 0}
    assert ds.reading is not None and (ds.reading.records, ds.reading.used) == (20, 18)
    assert ds.reading.dropped == {"before the odometry": 1, "after the odometry": 1}
    # a first and a last scan outside the odometry are the usual quirk, in a short file too
    # (FEW_DROPPED); more than that and more than a tenth is not a result, strict or lenient
    short = bags.write(tmp_path / "short.bag", _spec(bags, odometry=odometry[1:4]))
    few = read_rosbag(short)
    assert few.reading is not None and (few.reading.records, few.reading.used) == (4, 2)
    shorter = bags.write(tmp_path / "shorter.bag", _spec(bags, odometry=odometry[1:3]))
    for lenient in (False, True):
        with pytest.raises(
            DatasetFormatError,
            match=r"3 of 4 scans could not be used \(1 before the odometry, 2 after the odometry\)",
        ):
            read_rosbag(shorter, {"lenient": lenient})


def test_a_repeated_odometry_message_is_dropped_and_counted(bags, tmp_path):
    odometry = [bags.Odom(round(t * S), _odom_pose(k)) for k, t in enumerate(ODOM_T)]
    repeat = bags.Odom(odometry[2].stamp_ns, odometry[2].pose, bag_ns=odometry[2].stamp_ns + 1)
    spec = _spec(bags, odometry=[*odometry[:3], repeat, *odometry[3:]])
    ds = read_rosbag(_write(bags, tmp_path, spec))
    assert ds.metadata["odometry_repeats_dropped"] == 1
    assert len(_odometry(ds)) == 4


# ------------------------------------------------------------------------ odometry from /tf
def _tf(stamps_s: list[float], child: str = "base_link") -> list:
    return [(round(t * S), "odom", child, _odom_pose(k)) for k, t in enumerate(stamps_s)]


def test_odometry_from_tf_when_the_bag_has_no_odometry_topic(bags, tmp_path):
    """No /odom, the odometry as /tf odom → base_link at the odometry's stamps: the Odometry
    events are those transforms interpolated to the scan stamps, as from the topic."""
    path = _write(bags, tmp_path, _spec(bags, odometry=[], tf=_tf(ODOM_T)))
    ds = read_rosbag(path)
    got = np.array([e.pose for e in _odometry(ds)])
    # scan j (10.0 + 0.1 j) is halfway between transforms j and j + 1 (9.95 + 0.1 j, ...)
    expected = np.array(
        [[0.2 * j + 0.1, -0.1 * j - 0.05, wrap_angle(3.1 + 0.2 * j)] for j in range(4)]
    )
    np.testing.assert_allclose(got[:, :2], expected[:, :2], rtol=0, atol=1e-9)
    np.testing.assert_allclose(wrap_angle(got[:, 2] - expected[:, 2]), 0.0, atol=1e-9)
    assert [e.t for e in _odometry(ds)] == [10.0, 10.1, 10.2, 10.3]
    (tmp_path / "topic").mkdir()
    from_topic = read_rosbag(_write(bags, tmp_path / "topic", _spec(bags)))
    np.testing.assert_array_equal(got, [e.pose for e in _odometry(from_topic)])
    assert ds.metadata["odometry_topic"] == "/tf"
    assert ds.metadata["odometry_from"] == "/tf (odom → base_link)"
    assert from_topic.metadata["odometry_from"] == "/odom"
    assert "raw odometry (/tf (odom → base_link))" in ds.description
    assert ds.reading is not None and ds.reading.notes == ("odometry from /tf (odom → base_link)",)
    assert ds.metadata["mounting_from"] == "/tf_static: base_link → laser"
    # asked for the topic only: the scans alone; the twist's direction needs a topic
    alone = read_rosbag(path, {"odometry_source": "topic"})
    assert alone.motion is None and not _odometry(alone) and len(_scans(alone)) == 4
    assert alone.reading is not None and alone.reading.notes == ("no odometry: the scans alone",)
    with pytest.raises(DatasetFormatError, match=r"'twist' needs the twist of an odometry topic"):
        read_rosbag(path, {"odometry_direction": "twist"})


def test_odometry_from_tf_chains_a_static_base_footprint_and_is_chosen_over_the_topic(
    bags, tmp_path
):
    """/odom and /tf odom → base_footprint (at the scan stamps) with /tf_static
    base_footprint → base_link: ``odometry_source="tf"`` reads T_odom_base =
    T_odom_footprint ⊕ T_footprint_base; ``"auto"`` keeps the topic."""
    fixed = (0.1, -0.05, 0.3)
    tf_static = [("base_footprint", "base_link", fixed), ("base_link", "laser", (0.0, 0.0, 0.0))]
    stamps = [ns / S for ns in SCAN_NS]
    spec = _spec(bags, tf=_tf(stamps, "base_footprint"), tf_static=tf_static)
    path = _write(bags, tmp_path, spec)
    ds = read_rosbag(path, {"odometry_source": "tf"})
    got = np.array([e.pose for e in _odometry(ds)])
    fx, fy, fyaw = fixed
    for j, pose in enumerate(got):
        x, y, yaw = _odom_pose(j)
        expected = (
            x + math.cos(yaw) * fx - math.sin(yaw) * fy,
            y + math.sin(yaw) * fx + math.cos(yaw) * fy,
            yaw + fyaw,
        )
        np.testing.assert_allclose(pose[:2], expected[:2], rtol=0, atol=1e-9)
        assert float(wrap_angle(pose[2] - expected[2])) == pytest.approx(0.0, abs=1e-9)
    assert ds.metadata["odometry_from"] == "/tf (odom → base_footprint → base_link)"
    assert read_rosbag(path).metadata["odometry_from"] == "/odom"
    with pytest.raises(
        DatasetFormatError,
        match=r"no transform odom → robot on /tf \(transforms from 'odom': odom → base_footprint\)",
    ):
        read_rosbag(path, {"odometry_source": "tf", "base_frame": "robot"})
    (tmp_path / "bare").mkdir()
    bare = _write(bags, tmp_path / "bare", _spec(bags))
    with pytest.raises(DatasetFormatError, match=r"odometry from tf asked, but the bag has no /tf"):
        read_rosbag(bare, {"odometry_source": "tf"})


# ------------------------------------------------------------------------ typed errors
def test_missing_topic_and_wrong_type_name_the_topic_and_list_the_bag(bags, tmp_path):
    path = _write(bags, tmp_path, _spec(bags))
    with pytest.raises(DatasetFormatError, match=r"no topic '/laser'.*/scan \(sensor_msgs/msg/La"):
        read_rosbag(path, {"scan_topic": "/laser"})
    with pytest.raises(DatasetFormatError, match=r"'/scan' holds sensor_msgs/msg/LaserScan, ex"):
        read_rosbag(path, {"odom_topic": "/scan"})
    with pytest.raises(DatasetFormatError) as info:
        read_rosbag(path, {"odom_topic": "/odometry"})
    assert info.value.path == path and "/odom (nav_msgs/msg/Odometry)" in str(info.value)


def test_a_bag_without_odometry_is_read_as_scans_alone_and_says_so(bags, tmp_path):
    """No odometry topic at all (and the default topic asked): the scans only, no motion
    model, the description and metadata say so; explicitly asking for none does the same on
    a bag that has odometry; a named topic that is absent stays an error."""
    bare = _write(bags, tmp_path, _spec(bags, odometry=[]))
    ds = read_rosbag(bare)
    assert ds.motion is None and not _odometry(ds) and len(_scans(ds)) == len(SCAN_NS)
    assert ds.metadata["odometry_topic"] is None
    assert "no odometry (scan matching alone)" in ds.description
    (tmp_path / "f").mkdir()
    full = _write(bags, tmp_path / "f", _spec(bags))
    none = read_rosbag(full, {"odom_topic": None})
    assert none.motion is None and len(_scans(none)) == len(SCAN_NS)
    with pytest.raises(DatasetFormatError, match=r"no topic '/wheels'"):
        read_rosbag(bare, {"odom_topic": "/wheels"})


@pytest.mark.parametrize("bad", [math.nan, -0.5])
def test_nan_or_negative_range_is_an_error_or_lenient_no_return(bags, tmp_path, bad):
    ranges = [list(r) for r in RANGES]
    ranges[2][3] = bad
    scans = [bags.Scan(ns, r) for ns, r in zip(SCAN_NS, ranges, strict=True)]
    path = _write(bags, tmp_path, _spec(bags, scans=scans))
    with pytest.raises(DatasetFormatError, match=r"/scan message 2: beam 3") as info:
        read_rosbag(path)
    assert str(path) in str(info.value)
    ds = read_rosbag(path, {"lenient": True})
    assert _scans(ds)[2].ranges.tolist() == [4.0, 4.0, 4.0, 10.0, 4.0]
    assert ds.metadata["readings"]["invalid_readings"] == 1
    assert ds.metadata["lenient"]["counts"] == {"invalid_readings": 1}


def test_angle_max_one_increment_off_is_read_with_the_increment_and_noted_once(bags, tmp_path):
    """5 beams from -1 by 0.5 end at 1.0 rad; every scan says angle_max 1.5 (one increment
    over) or 0.5 (one under): read, the beams at angle_min + i·increment, one note."""
    scans = [bags.Scan(ns, r, angle_max=1.5) for ns, r in zip(SCAN_NS, RANGES, strict=True)]
    scans[2].angle_max = 0.5
    ds = read_rosbag(_write(bags, tmp_path, _spec(bags, scans=scans)))
    assert len(_scans(ds)) == 4
    np.testing.assert_array_equal(ds.laser.beam_angles, -1.0 + 0.5 * np.arange(5))
    assert ds.reading is not None and ds.reading.dropped == {} and ds.reading.repaired == {}
    assert ds.reading.notes == (
        "angle_max up to 1.00 increments off the last beam on 4 of 4 scans: the beams are "
        "angle_min + i·angle_increment",
    )
    assert ds.metadata["lenient"]["counts"] == {}


def test_angle_max_two_increments_off_is_an_error_or_dropped(bags, tmp_path):
    scans = [bags.Scan(ns, r) for ns, r in zip(SCAN_NS, RANGES, strict=True)]
    scans[1].angle_max = 2.0  # the last beam is at 1.0: two increments of 0.5 off
    path = _write(bags, tmp_path, _padded(bags, _spec(bags, scans=scans)))
    with pytest.raises(
        DatasetFormatError,
        match=r"/scan message 1: 5 beams from angle_min -1 by 0.5 end at 1 rad, but angle_max "
        r"is 2 \(more than 1.5 increments off\)",
    ) as info:
        read_rosbag(path)
    assert info.value.path == path and str(path) in str(info.value)
    ds = read_rosbag(path, {"lenient": True})
    assert [e.t for e in _scans(ds)][:3] == [10.0, 10.2, 10.3]
    assert ds.metadata["lenient"]["counts"] == {"geometry": 1}
    assert ds.reading is not None and ds.reading.dropped == {"bad geometry": 1}
    assert (ds.reading.records, ds.reading.used, ds.reading.notes) == (20, 19, ())


def test_a_scan_with_another_geometry_is_an_error(bags, tmp_path):
    scans = [bags.Scan(ns, r) for ns, r in zip(SCAN_NS, RANGES, strict=True)]
    scans[3] = bags.Scan(SCAN_NS[3], [1.0, 2.0, 3.0, 4.0])
    with pytest.raises(DatasetFormatError, match=r"/scan message 3: beam geometry differs"):
        read_rosbag(_write(bags, tmp_path, _spec(bags, scans=scans)))


def test_scan_stamps_out_of_order_are_an_error_or_dropped(bags, tmp_path):
    order = [SCAN_NS[0], SCAN_NS[2], SCAN_NS[1], SCAN_NS[3]]  # header stamps; bag times rise
    scans = [
        bags.Scan(ns, r, bag_ns=SCAN_NS[i])
        for i, (ns, r) in enumerate(zip(order, RANGES, strict=True))
    ]
    path = _write(bags, tmp_path, _padded(bags, _spec(bags, scans=scans)))
    with pytest.raises(DatasetFormatError, match=r"/scan message 2: stamp 10.100000000 not later"):
        read_rosbag(path)
    ds = read_rosbag(path, {"lenient": True})
    assert [e.t for e in _scans(ds)][:3] == [10.0, 10.2, 10.3]
    assert ds.reading is not None and ds.reading.dropped == {"stamp out of order": 1}
    assert ds.metadata["lenient"]["counts"] == {"scans_out_of_order": 1}


def test_odometry_out_of_order_is_an_error(bags, tmp_path):
    odometry = [bags.Odom(round(t * S), _odom_pose(k)) for k, t in enumerate(ODOM_T)]
    odometry[2].stamp_ns, odometry[2].bag_ns = odometry[1].stamp_ns - 1, odometry[2].stamp_ns
    path = _write(bags, tmp_path, _spec(bags, odometry=odometry))
    with pytest.raises(DatasetFormatError, match=r"/odom message 2: stamp not later"):
        read_rosbag(path)
    assert read_rosbag(path, {"lenient": True}).metadata["lenient"]["counts"] == {
        "odometry_out_of_order": 1
    }


def test_odometry_gap_longer_than_the_limit_is_an_error_or_dropped(bags, tmp_path):
    odometry = [bags.Odom(round(t * S), _odom_pose(k)) for k, t in enumerate(ODOM_T)]
    # odometry at 9.95, 10.05, 10.25, 10.35 ...: scans 10.1 and 10.2 lie in a 0.2 s gap
    spec = _padded(bags, _spec(bags, odometry=[*odometry[:2], *odometry[3:]]))
    path = _write(bags, tmp_path, spec)
    with pytest.raises(DatasetFormatError, match=r"/scan message 1: scan at t=10.1.* 0.200 s gap"):
        read_rosbag(path, {"max_odom_gap": 0.15})
    ds = read_rosbag(path, {"max_odom_gap": 0.15, "lenient": True})
    assert [e.t for e in _scans(ds)][:2] == [10.0, 10.3]
    assert ds.metadata["dropped"]["odometry_gap"] == 2
    assert ds.reading is not None and ds.reading.dropped == {"in an odometry gap": 2}
    assert (ds.reading.records, ds.reading.used) == (20, 18)


def test_lenient_read_dropping_more_than_a_tenth_of_the_scans_is_an_error(bags, tmp_path):
    """Three of 20 scans in an odometry gap: lenient would keep 17 (85%); the reader refuses
    rather than silently drop more than 10% (``reading.check_dropped_share``)."""
    odometry = [bags.Odom(round(t * S), _odom_pose(k)) for k, t in enumerate(ODOM_T)]
    spec = _padded(bags, _spec(bags, odometry=[odometry[0], odometry[1], odometry[4]]))
    path = _write(bags, tmp_path, spec)  # scans 10.1, 10.2, 10.3 in a 0.3 s gap
    assert len(_scans(read_rosbag(path, {"max_odom_gap": 0.35, "lenient": True}))) == 20
    with pytest.raises(
        DatasetFormatError, match=r"3 of 20 scans could not be used \(3 in an odometry gap\)"
    ) as info:
        read_rosbag(path, {"max_odom_gap": 0.25, "lenient": True})
    assert info.value.path == path


def test_odometry_with_a_zero_quaternion_is_an_error(bags, tmp_path):
    odometry = [bags.Odom(round(t * S), _odom_pose(k)) for k, t in enumerate(ODOM_T)]
    odometry[3].quaternion = (0.0, 0.0, 0.0, 0.0)
    path = _write(bags, tmp_path, _spec(bags, odometry=odometry))
    with pytest.raises(DatasetFormatError, match=r"/odom message 3: .*quaternion of norm 0"):
        read_rosbag(path)
    ds = read_rosbag(path, {"lenient": True})
    assert ds.metadata["lenient"]["counts"] == {"bad_odometry": 1}
    assert len(_scans(ds)) == 4  # 10.15 missing: scans 1, 2 interpolate over 10.05..10.35


def test_truncated_corrupt_and_missing_bags_are_typed_errors(bags, tmp_path):
    path = _write(bags, tmp_path, _spec(bags))
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(DatasetFormatError, match=r"cannot read the bag") as info:
        read_rosbag(cut)
    assert info.value.path == cut
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 8)
    with pytest.raises(DatasetFormatError, match=r"junk.bag: cannot read the bag"):
        read_rosbag(junk)
    with pytest.raises(DataNotFoundError, match=r"nothing.bag: not found"):
        read_rosbag(tmp_path / "nothing.bag")


def test_options_are_checked():
    with pytest.raises(ConfigError, match="max_odom_gap"):
        RosbagOptions(max_odom_gap=0.0)
    with pytest.raises(ConfigError, match="odometry_source: expected 'auto', 'topic' or 'tf'"):
        RosbagOptions(odometry_source="wheels")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="odom_frame: expected a frame name"):
        RosbagOptions(odom_frame="/")
    with pytest.raises(ConfigError, match="scan_topic"):
        RosbagOptions(scan_topic="")
    with pytest.raises(ConfigError, match="unknown"):
        read_rosbag("x.bag", {"scan_topik": "/scan"})
    assert RosbagOptions(max_odom_gap=math.inf).max_odom_gap == math.inf
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ConfigError, match="max_duration_s"):
            RosbagOptions(max_duration_s=bad)


# ------------------------------------------------------------------------ the Freiburg bags
FREIBURG = {
    # name: (scan messages, scans kept, beams, max range, relations)
    "intel-raw": (13_631, 13_630, 180, 80.0, 2984),
    "aces-raw": (7_374, 7_374, 180, 50.0, 1279),
    "fr079-raw": (4_934, 4_933, 360, 80.0, 1685),
}


@pytest.fixture(scope="module")
def freiburg(data_root: Path) -> dict:
    missing = [f for name in FREIBURG for f in DATASETS[name].files if not (data_root / f).exists()]
    if missing:
        pytest.skip(f"real data not found under {data_root}: {', '.join(missing)}")
    return {name: load_dataset(name, data_root=data_root) for name in FREIBURG}


@pytest.mark.realdata
@pytest.mark.parametrize("name", list(FREIBURG))
def test_freiburg_bags_counts_geometry_and_relation_stamps(freiburg, name):
    ds = freiburg[name]
    messages, kept, beams, max_range, n_rel = FREIBURG[name]
    md = ds.metadata
    assert md["scan_messages"] == messages and md["scans"] == kept
    assert ds.counts() == {"Odometry": kept, "LaserScan": kept}
    assert ds.laser.n_beams == beams and ds.laser.max_range == max_range
    assert ds.laser.beam_angles[0] == float(F32(-math.pi / 2))
    assert abs(ds.laser.beam_angles[-1] - math.pi / 2) < 1e-6
    rel = ds.truth.relations
    assert rel is not None and len(rel) == n_rel
    times = np.array([e.t for e in _scans(ds)])
    # every relation stamp is a scan stamp, exactly (float64 sec + nanosec·1e-9)
    assert np.isin(rel.stamps, times).all()


@pytest.mark.realdata
def test_a_cut_log_keeps_its_first_seconds_and_the_relations_within_them(freiburg, data_root):
    whole = freiburg["intel-raw"]
    cut = load_dataset("intel-raw", options={"max_duration_s": 300.0}, data_root=data_root)
    times = np.array([e.t for e in _scans(cut)])
    every = np.array([e.t for e in _scans(whole)])
    assert times[0] == every[0] and np.array_equal(times, every[every <= every[0] + 300.0])
    rel, all_rel = cut.truth.relations, whole.truth.relations
    inside = (all_rel.t1 <= times[-1]) & (all_rel.t2 <= times[-1])
    assert 0 < len(rel) == int(inside.sum()) < len(all_rel)
    assert np.array_equal(rel.deltas, all_rel.deltas[inside])
    assert cut.metadata["cut_at_s"] == 300.0 and f"{len(rel)} reference relations" in (
        cut.description
    )


@pytest.mark.realdata
def test_freiburg_dropped_scans_mounting_and_repeats(freiburg):
    assert freiburg["intel-raw"].metadata["dropped"]["after_odometry"] == 1
    assert freiburg["fr079-raw"].metadata["dropped"]["before_odometry"] == 1
    assert freiburg["aces-raw"].metadata["odometry_repeats_dropped"] == 1
    readings = {name: freiburg[name].reading for name in FREIBURG}
    assert [(r.records, r.used, dict(r.dropped), r.notes) for r in readings.values()] == [
        (13_631, 13_630, {"after the odometry": 1}, ()),
        (7_374, 7_374, {}, ()),
        (4_934, 4_933, {"before the odometry": 1}, ()),
    ]
    # The registered fr079-raw overrides the bag's /tf_static (+0.04 m) with the original
    # log's robot_frontlaser_offset (-0.04 m), the frame of the benchmark's relations.
    assert freiburg["fr079-raw"].laser.mounting == (-0.04, 0.0, 0.0)
    assert freiburg["fr079-raw"].metadata["mounting_from"] == "option mounting"
    assert freiburg["intel-raw"].laser.mounting == (0.0, 0.0, 0.0)
    assert freiburg["aces-raw"].laser.mounting == (0.0, 0.0, 0.0)


@pytest.mark.realdata
def test_intel_raw_odometry_scores_as_published_on_short_relations(freiburg):
    """DATA.md: raw odometry scores about 0.03 m / 1.7° on the Intel relations shorter than
    3 s — a check of the quaternion → yaw conversion and of the interpolation."""
    ds = freiburg["intel-raw"]
    rel = ds.truth.relations
    times = np.array([e.t for e in _odometry(ds)])
    poses = np.array([e.pose for e in _odometry(ds)])
    short = (rel.t2 - rel.t1) < 3.0
    i1 = np.searchsorted(times, rel.t1[short])
    i2 = np.searchsorted(times, rel.t2[short])
    est = between(poses[i1], poses[i2])
    err = between(rel.deltas[short], est)
    trans = float(np.mean(np.hypot(err[:, 0], err[:, 1])))
    rot = float(np.degrees(np.mean(np.abs(wrap_angle(err[:, 2])))))
    # measured: 0.0331 m, 1.70°
    assert 0.030 < trans < 0.036 and 1.6 < rot < 1.8, (trans, rot)


@pytest.mark.realdata
def test_fr079_raw_odometry_backs_up_where_the_relations_do(freiburg, data_root):
    """Freiburg 079's /odom poses never go backward (integrated from the unsigned speed);
    the registered fr079-raw takes the direction from the twist (docs/relations.md)."""

    def short_relations(ds):
        rel = ds.truth.relations
        times = np.array([e.t for e in _odometry(ds)])
        poses = np.array([e.pose for e in _odometry(ds)])
        short = (rel.t2 - rel.t1) < 3.0
        est = between(
            poses[np.searchsorted(times, rel.t1[short])],
            poses[np.searchsorted(times, rel.t2[short])],
        )
        err = between(rel.deltas[short], est)
        back = rel.deltas[short][:, 0] < -0.1
        agree = int(np.count_nonzero(est[back, 0] < 0.0))
        return float(np.mean(np.hypot(err[:, 0], err[:, 1]))), int(back.sum()), agree

    as_poses = load_dataset(
        "fr079-raw", options={"odometry_direction": "pose"}, data_root=data_root
    )
    # measured: 966 short relations, 27 of them backing up more than 0.1 m;
    # 0.0569 m with the poses' direction (none backs up), 0.0380 m with the twist's
    trans, back, agree = short_relations(as_poses)
    assert back == 27 and agree == 0 and 0.055 < trans < 0.059, (trans, back, agree)
    trans, back, agree = short_relations(freiburg["fr079-raw"])
    assert back == 27 and agree == 27 and 0.036 < trans < 0.040, (trans, back, agree)


@pytest.mark.realdata
def test_aces_odometry_from_tf_is_the_odom_topics(freiburg, data_root):
    """The Freiburg bags carry their odometry twice, on /odom and as /tf odom → base_link:
    read from /tf, ACES's Odometry events are bit-identical to the registered ones (so are
    Intel's and Freiburg 079's with the poses' direction, measured)."""
    ds = read_rosbag(
        data_root / DATASETS["aces-raw"].files[0],
        {**DATASETS["aces-raw"].defaults, "odometry_source": "tf"},
    )
    registered = freiburg["aces-raw"]
    assert ds.metadata["odometry_from"] == "/tf (odom → base_link)"
    assert [e.t for e in _odometry(ds)] == [e.t for e in _odometry(registered)]
    np.testing.assert_array_equal(
        [e.pose for e in _odometry(ds)], [e.pose for e in _odometry(registered)]
    )
