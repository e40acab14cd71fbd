"""Raw CARMEN logs: hand-written logs of each laser line type (FLASER new and old,
ROBOTLASER1, RAWLASER with ODOM lines) read back exactly, and the line errors."""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import LaserScan, Odometry
from slamkit.datasets.carmen_raw import CarmenRawOptions, parse_carmen_raw, read_carmen_raw_log
from slamkit.errors import ConfigError, DatasetFormatError
from slamkit.geometry import wrap_angle
from slamkit.geometry.pose2 import compose

MOUNT = (0.1, 0.0, 0.0)  # laser 10 cm ahead of the robot
ODOM = [(1.0, 2.0, 0.5), (1.2, 2.1, 0.6), (1.4, 2.3, 3.1)]
RANGES = [[1.0, 2.0, 3.0, 25.0, 20.0], [0.5, 0.25, 19.99, 4.0, 7.5], [6.0, 6.0, 6.0, 6.0, 6.0]]
PARAMS = [
    "PARAM laser_front_laser_fov 180",
    "PARAM laser_front_laser_resolution 45",
    "PARAM robot_front_laser_max 20",
]


def _nums(values) -> str:
    return " ".join(repr(float(v)) for v in values)


def _flaser(k: int, new: bool = True) -> str:
    laser = compose(np.array(ODOM[k]), np.array(MOUNT))
    tail = (
        f" {100.0 + k * 0.25!r} myhost {100.01 + k * 0.25!r}" if new else f" {100.0 + k * 0.25!r}"
    )
    return f"FLASER 5 {_nums(RANGES[k])} {_nums(laser)} {_nums(ODOM[k])}" + tail


def _write(tmp_path: Path, lines: list[str], name: str = "log.clf", gz: bool = False) -> Path:
    path = tmp_path / name
    text = "\n".join(lines) + "\n"
    path.write_bytes(gzip.compress(text.encode()) if gz else text.encode())
    return path


def _events(ds, kind):
    return [e for e in ds.events if isinstance(e, kind)]


@pytest.mark.parametrize("new", [True, False])
def test_flaser_new_and_old_formats_read_exactly(tmp_path, new):
    path = _write(tmp_path, ["# a raw log", *PARAMS, *(_flaser(k, new) for k in range(3))])
    ds = read_carmen_raw_log(path)
    scans, odom = _events(ds, LaserScan), _events(ds, Odometry)
    assert [e.t for e in scans] == [100.0, 100.25, 100.5] == [e.t for e in odom]
    np.testing.assert_array_equal(
        np.array([e.ranges for e in scans]),
        [[1.0, 2.0, 3.0, 20.0, 20.0], [0.5, 0.25, 19.99, 4.0, 7.5], [6.0] * 5],
    )
    np.testing.assert_array_equal(np.array([e.pose for e in odom]), ODOM)  # the raw odometry
    np.testing.assert_allclose(ds.laser.beam_angles, np.deg2rad([-90, -45, 0, 45, 90]))
    assert ds.laser.max_range == 20.0 and ds.metadata["max_range_from"] == (
        "PARAM robot_front_laser_max"
    )
    np.testing.assert_allclose(ds.laser.mounting, MOUNT, atol=1e-12)
    assert ds.metadata["mounting_spread"] < 1e-12
    assert ds.metadata["max_range_readings"] == 2
    assert ds.metadata["laser_message"] == "FLASER" and ds.name == "log.clf"
    np.testing.assert_array_equal(ds.initial_pose, ODOM[0])


def test_gzip_is_recognised_by_its_content(tmp_path):
    path = _write(tmp_path, [*PARAMS, _flaser(0), _flaser(1)], name="log.clf", gz=True)
    assert [e.t for e in _events(read_carmen_raw_log(path), LaserScan)] == [100.0, 100.25]


def _robotlaser(t: float, ranges, *, fov: float = math.pi, remissions=(0.5, 0.6)) -> str:
    laser = compose(np.array(ODOM[0]), np.array(MOUNT))
    start, res = -math.pi / 2, math.pi / 4
    head = f"ROBOTLASER1 0 {start!r} {fov!r} {res!r} 30.0 0.01 0 {len(ranges)} {_nums(ranges)}"
    rem = f"{len(remissions)} {_nums(remissions)}" if remissions else "0"
    return (
        f"{head} {rem} {_nums(laser)} {_nums(ODOM[0])} 0.3 0.1 0.5 0.2 0.0 {t!r} host {t + 0.01!r}"
    )


def test_robotlaser1_reads_its_geometry_poses_and_max_range(tmp_path):
    lines = [
        _robotlaser(5.0, [1.0, 31.0, 30.0, 2.0, 3.0]),
        _robotlaser(5.5, [4.0] * 5, remissions=()),
    ]
    ds = read_carmen_raw_log(_write(tmp_path, lines))
    scans = _events(ds, LaserScan)
    assert [e.t for e in scans] == [5.0, 5.5]
    assert scans[0].ranges.tolist() == [1.0, 30.0, 30.0, 2.0, 3.0]
    np.testing.assert_allclose(ds.laser.beam_angles, -math.pi / 2 + math.pi / 4 * np.arange(5))
    assert ds.laser.max_range == 30.0
    assert ds.metadata["max_range_from"] == "ROBOTLASER1 max range field"
    np.testing.assert_array_equal(_events(ds, Odometry)[1].pose, ODOM[0])
    np.testing.assert_allclose(ds.laser.mounting, MOUNT, atol=1e-12)


def test_robotlaser1_fov_that_disagrees_with_the_beams_is_a_line_error(tmp_path):
    path = _write(tmp_path, [_robotlaser(5.0, [1.0] * 5), _robotlaser(5.5, [1.0] * 5, fov=2.0)])
    with pytest.raises(DatasetFormatError, match=r"log.clf:2: ROBOTLASER1: 5 beams at"):
        read_carmen_raw_log(path)


def _rawlaser(t: float, ranges, kind: str = "RAWLASER1") -> str:
    start, res = -1.0, 0.5
    return (
        f"{kind} 0 {start!r} 2.0 {res!r} 8.0 0.01 0 {len(ranges)} {_nums(ranges)} 0 "
        f"{t!r} host {t!r}"
    )


ODOM_LINES = [
    "ODOM 0.0 0.0 3.0 0.2 0.1 0.0 0.9 host 0.9",  # new format
    "ODOM 0.2 0.1 -3.0 0.2 0.1 0.0 1.1",  # old format (no host, logger_ts)
    "ODOM 0.4 0.3 -2.8 0.2 0.1 0.0 1.3 host 1.3",
]


def test_rawlaser_takes_its_odometry_from_odom_lines_interpolated_to_the_scans(tmp_path):
    lines = [
        ODOM_LINES[0],
        _rawlaser(1.0, [1.0, 2.0, 9.0, 8.0, 7.0]),
        ODOM_LINES[1],
        _rawlaser(1.2, [3.0] * 5),
        ODOM_LINES[2],
        _rawlaser(1.5, [3.0] * 5),  # after the last ODOM line: dropped
    ]
    ds = read_carmen_raw_log(_write(tmp_path, lines, name="raw.log"))
    scans, odom = _events(ds, LaserScan), _events(ds, Odometry)
    assert [e.t for e in scans] == [1.0, 1.2]
    assert scans[0].ranges.tolist() == [1.0, 2.0, 8.0, 8.0, 7.0]
    np.testing.assert_allclose(ds.laser.beam_angles, [-1.0, -0.5, 0.0, 0.5, 1.0])
    # half way: heading from 3.0 to -3.0 goes the short way, through pi
    np.testing.assert_allclose(odom[0].pose[:2], [0.1, 0.05], atol=1e-12)
    assert float(wrap_angle(odom[0].pose[2] - math.pi)) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(odom[1].pose, [0.3, 0.2, -2.9], atol=1e-12)
    assert ds.metadata["dropped"] == {"before_odometry": 0, "after_odometry": 1, "odometry_gap": 0}
    assert ds.laser.mounting == (0.0, 0.0, 0.0) and ds.laser.max_range == 8.0
    assert ds.metadata["odometry_from"] == "ODOM lines interpolated to the scan stamps"


def test_rawlaser_in_an_odom_gap_is_a_line_error(tmp_path):
    # ODOM at 0.9 and 1.3: the scan at 1.0 is in a 0.4 s gap, the one at 1.3 at an ODOM stamp
    lines = [ODOM_LINES[0], _rawlaser(1.0, [1.0] * 5), ODOM_LINES[2], _rawlaser(1.3, [2.0] * 5)]
    path = _write(tmp_path, lines)
    with pytest.raises(DatasetFormatError, match=r"log.clf:2: RAWLASER1: scan at t=1.0 .* 0.400 s"):
        read_carmen_raw_log(path, {"max_odom_gap": 0.3})
    assert read_carmen_raw_log(path).metadata["scans"] == 2  # 0.4 s < 0.5 s by default
    lenient = read_carmen_raw_log(path, {"max_odom_gap": 0.3, "lenient": True})
    assert lenient.metadata["dropped"]["odometry_gap"] == 1
    (odom,) = _events(lenient, Odometry)
    assert odom.t == 1.3 and odom.pose.tolist() == [0.4, 0.3, -2.8]


def test_the_laser_is_chosen_first_found_or_by_option(tmp_path):
    lines = [*PARAMS, ODOM_LINES[0], _rawlaser(1.0, [1.0] * 5, "RAWLASER2"), _flaser(0)]
    lines += [ODOM_LINES[1], _flaser(1)]
    path = _write(tmp_path, lines)
    assert read_carmen_raw_log(path).metadata["laser_message"] == "FLASER"
    raw = read_carmen_raw_log(path, {"laser": "RAWLASER2"})
    assert raw.metadata["laser_message"] == "RAWLASER2" and raw.metadata["scans"] == 1
    with pytest.raises(DatasetFormatError, match=r"no ROBOTLASER1 lines in the log; it has: FLA"):
        read_carmen_raw_log(path, {"laser": "ROBOTLASER1"})
    with pytest.raises(ConfigError, match="laser"):
        CarmenRawOptions(laser="LASER9")


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        (_flaser(1).replace(" myhost", ""), r"log.clf:5: FLASER: expected 5 ranges"),
        (_flaser(1).replace("FLASER 5 0.5", "FLASER 5 x"), r"log.clf:5: FLASER: a field is not"),
        (_flaser(1).replace("FLASER 5 0.5", "FLASER 5 nan"), r"log.clf:5: FLASER: ranges must"),
        (_flaser(1).replace("FLASER 5 0.5", "FLASER 5 -0.5"), r"log.clf:5: FLASER: ranges must"),
        ("ODOM 1 2 x 0 0 0 5.0", r"log.clf:5: ODOM: expected x y theta"),
        ("FLASER 4 1 2 3 4 0 0 0 0 0 0 100.3", r"log.clf:5: FLASER: 4 beams, the log has 5"),
    ],
)
def test_malformed_lines_name_file_and_line_or_are_skipped(tmp_path, bad, message):
    lines = [*PARAMS, _flaser(0), bad, _flaser(2)]
    path = _write(tmp_path, lines)
    with pytest.raises(DatasetFormatError, match=message) as info:
        read_carmen_raw_log(path)
    assert info.value.line == 5
    ds = read_carmen_raw_log(path, {"lenient": True})
    assert ds.metadata["skipped_lines"]["count"] == 1
    assert ds.metadata["skipped_lines"]["first"][0]["line"] == 5
    assert [e.t for e in _events(ds, LaserScan)] == [100.0, 100.5]


def test_a_stamp_that_goes_back_is_placed_between_its_neighbours(tmp_path):
    # Formerly an error: the line order is the log's order, and a stamp is only evidence.
    lines = [*PARAMS, _flaser(0), _flaser(1).replace(" 100.25 ", " 99.0 "), _flaser(2)]
    ds = read_carmen_raw_log(_write(tmp_path, lines))
    assert [e.t for e in _events(ds, LaserScan)] == [100.0, 100.25, 100.5]
    assert ds.reading is not None and dict(ds.reading.repaired) == {"stamps out of order": 1}


def test_a_log_without_laser_lines_is_an_error(tmp_path):
    with pytest.raises(DatasetFormatError, match=r"no FLASER or ROBOTLASER1 or .* it has: ODOM"):
        read_carmen_raw_log(_write(tmp_path, ODOM_LINES))


def test_parse_keeps_the_odom_lines_in_time_order(tmp_path):
    log = parse_carmen_raw(
        _write(tmp_path, [ODOM_LINES[0], ODOM_LINES[0], _rawlaser(1.0, [1.0] * 5)])
    )
    assert log.odom_repeats == 1 and log.odom_times.tolist() == [0.9]
    np.testing.assert_array_equal(log.odom_lines, [[0.0, 0.0, float(wrap_angle(3.0))]])
