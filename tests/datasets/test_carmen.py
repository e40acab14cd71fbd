"""CARMEN and DP-SLAM log readers: counts, geometry, first values, errors, lenient mode.

Small hand-made logs (plain and gzip) pin down the format rules; the real logs under
``SLAMKIT_DATA`` (skipped when absent) pin down counts and first values, read off the files
with ``zcat | head``.
"""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import LaserScan, Odometry
from slamkit.datasets.carmen import (
    CarmenOptions,
    beam_angles_from_geometry,
    load_aces,
    load_freiburg079,
    load_intel,
    load_loop5,
    parse_carmen_log,
    read_carmen_log,
    read_dpslam_log,
)
from slamkit.errors import ConfigError, DatasetFormatError
from slamkit.models import odometry_control

# --------------------------------------------------------------------------------------------
# hand-made logs
# --------------------------------------------------------------------------------------------


def _flaser(ranges: list[float] | np.ndarray, pose: tuple[float, float, float], t: float) -> str:
    r = " ".join(f"{v:g}" for v in ranges)
    x, y, th = pose
    return f"FLASER {len(ranges)} {r} {x} {y} {th} {x} {y} {th} {t} host {t}"


def _ranges(n: int = 180, first: float = 1.0) -> np.ndarray:
    return first + 0.01 * np.arange(n)


def _log(lines: list[str]) -> str:
    return "\n".join(lines) + "\n"


HEADER = [
    "# message formats defined: PARAM SYNC ODOM FLASER RLASER TRUEPOS",
    "PARAM robot_frontlaser_offset 0.0 nohost 0",
]


def _basic_log() -> list[str]:
    return [
        *HEADER,
        "ODOM 0 0 0 0 0 0 0.5 host 0.5",
        _flaser(_ranges(), (1.0, 2.0, 0.5), 1.0),
        "NEFF 30",
        "ODOM 5 5 5 0 0 0 1.5 host 1.5",  # wildly off, like the real ODOM lines: never used
        _flaser(_ranges(first=2.0), (1.5, 2.0, 0.5), 2.0),
        _flaser([*_ranges(first=3.0)[:-1], 95.0], (2.0, 2.5, 1.0), 3.0),
    ]


def _write(tmp_path: Path, lines: list[str], name: str = "log.log", gz: bool = False) -> Path:
    path = tmp_path / name
    data = _log(lines).encode()
    path.write_bytes(gzip.compress(data) if gz else data)
    return path


def test_hand_log_scans_truth_geometry_and_max_range(tmp_path):
    path = _write(tmp_path, _basic_log())
    ds = read_carmen_log(path, {"odometry_sigma_trans": 0.0, "odometry_sigma_rot_deg": 0.0})
    assert ds.counts() == {"Odometry": 3, "LaserScan": 3}
    # Odometry comes first at each scan time, then the scan.
    assert isinstance(ds.events[0], Odometry) and isinstance(ds.events[1], LaserScan)
    np.testing.assert_allclose(ds.truth.times, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(ds.truth.poses, [[1.0, 2.0, 0.5], [1.5, 2.0, 0.5], [2.0, 2.5, 1.0]])
    # 180 beams: 180° at 1°, from -90° counter-clockwise.
    assert ds.laser is not None and ds.laser.n_beams == 180
    np.testing.assert_allclose(np.rad2deg(ds.laser.beam_angles[[0, 1, 90, 179]]), [-90, -89, 0, 89])
    assert ds.laser.max_range == 80.0
    scans = [ev for ev in ds.events if isinstance(ev, LaserScan)]
    np.testing.assert_allclose(scans[0].ranges[:3], [1.0, 1.01, 1.02])
    assert scans[2].ranges[-1] == 80.0  # 95 m >= 80 m: "no return", stored as exactly 80
    assert ds.metadata["max_range_readings"] == 1
    # Noise-free odometry reproduces the corrected poses: ODOM lines play no part.
    odo = np.array([ev.pose for ev in ds.events if isinstance(ev, Odometry)])
    np.testing.assert_allclose(odo, ds.truth.poses, atol=1e-12)
    assert ds.metadata["odom_lines_ignored"] == 2
    assert ds.metadata["message_counts"] == {"PARAM": 1, "ODOM": 2, "FLASER": 3, "NEFF": 1}
    np.testing.assert_allclose(ds.initial_pose, [1.0, 2.0, 0.5])


def test_gzip_and_plain_files_read_the_same(tmp_path):
    plain = read_carmen_log(_write(tmp_path, _basic_log(), "a.log"), seed=4)
    packed = read_carmen_log(_write(tmp_path, _basic_log(), "b.log", gz=True), seed=4)
    for a, b in zip(plain.events, packed.events, strict=True):
        assert type(a) is type(b) and a.t == b.t
        np.testing.assert_array_equal(getattr(a, "ranges", getattr(a, "pose", None)),
                                      getattr(b, "ranges", getattr(b, "pose", None)))  # fmt: skip


def test_param_lines_set_max_range_and_geometry(tmp_path):
    lines = [
        "PARAM robot_front_laser_max 30.5 host 0",
        "PARAM laser_front_laser_resolution 0.5 host 0",
        _flaser([1.0] * 359 + [31.0], (0.0, 0.0, 0.0), 1.0),
    ]
    ds = read_carmen_log(_write(tmp_path, lines))
    assert ds.laser is not None and ds.laser.n_beams == 360
    np.testing.assert_allclose(np.rad2deg(ds.laser.beam_angles[[0, 1, 359]]), [-90, -89.5, 89.5])
    assert ds.laser.max_range == 30.5 and ds.metadata["max_range_from"].startswith("PARAM")
    assert ds.metadata["geometry_from"] == "PARAM"
    scan = next(ev for ev in ds.events if isinstance(ev, LaserScan))
    assert scan.ranges[-1] == 30.5
    # The options win over PARAM.
    ds2 = read_carmen_log(_write(tmp_path, lines, "c.log"), {"max_range": 20.0})
    assert ds2.laser is not None and ds2.laser.max_range == 20.0


def test_beam_angles_helper():
    np.testing.assert_allclose(
        np.rad2deg(beam_angles_from_geometry(181, 180.0, 1.0)[[0, 90, 180]]), [-90, 0, 90]
    )


# --------------------------------------------------------------------------------------------
# errors and lenient mode
# --------------------------------------------------------------------------------------------


def _with_line(line: str) -> list[str]:
    lines = _basic_log()
    lines.insert(5, line)  # becomes line 6 of the file
    return lines


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        (_flaser(_ranges(), (0, 0, 0), 1.7).replace("1.05 ", "1.05x ", 1), "not a number"),
        (_flaser(_ranges(), (0, 0, 0), 1.7).replace(" 1.05 ", " ", 1), "expected 186 numbers"),
        (_flaser(_ranges(179), (0, 0, 0), 1.7), "179 beams disagree"),
        (_flaser([math.nan, *_ranges(179)], (0, 0, 0), 1.7), "finite and >= 0"),
        (_flaser([-0.5, *_ranges(179)], (0, 0, 0), 1.7), "finite and >= 0"),
        ("FLASER x 1 2 3", "beam count"),
        ("ODOM 1 2 3", "ODOM"),
        ("NEFF", "NEFF"),
    ],
)
def test_malformed_line_names_file_and_line(tmp_path, bad, message):
    path = _write(tmp_path, _with_line(bad))
    with pytest.raises(DatasetFormatError, match=message) as info:
        read_carmen_log(path)
    assert info.value.line == 6
    assert info.value.path == path
    assert f"{path}:6: " in str(info.value)


def test_lenient_mode_skips_and_counts(tmp_path):
    lines = _basic_log()
    lines.insert(5, _flaser([math.nan, *_ranges(179)], (0, 0, 0), 1.7))
    lines.insert(3, "ODOM 1 2")
    lines.append(_flaser(_ranges(179), (0, 0, 0), 9.0))
    path = _write(tmp_path, lines)
    ds = read_carmen_log(path, {"lenient": True})
    assert ds.counts()["LaserScan"] == 3
    skipped = ds.metadata["skipped_lines"]
    assert skipped["count"] == 3
    assert [s["line"] for s in skipped["first"]] == [4, 7, 11]


def test_geometry_from_param_must_match_the_beam_count(tmp_path):
    lines = [
        "PARAM laser_front_laser_fov 180 host 0",
        "PARAM laser_front_laser_resolution 1.0 host 0",
        _flaser(_ranges(360), (0, 0, 0), 1.0),
    ]
    with pytest.raises(DatasetFormatError, match="360 beams do not match") as info:
        parse_carmen_log(_write(tmp_path, lines))
    assert info.value.line == 3


def test_an_unusual_beam_count_is_taken_over_180_degrees_and_said(tmp_path):
    path = _write(tmp_path, [_flaser(_ranges(100), (0, 0, 0), 1.0)])
    assumed = read_carmen_log(path)
    assert assumed.laser is not None
    np.testing.assert_allclose(
        np.rad2deg(assumed.laser.beam_angles[[0, 1, 99]]), [-90, -88.2, 88.2]
    )
    assert assumed.reading is not None
    assert assumed.reading.notes == ("no field of view stated: 100 beams taken over 180°",)
    ds = read_carmen_log(path, {"fov_deg": 99.0, "angular_resolution_deg": 1.0})
    assert ds.laser is not None and ds.laser.n_beams == 100
    np.testing.assert_allclose(np.rad2deg(ds.laser.beam_angles[[0, 99]]), [-49.5, 49.5])


def test_bad_options_and_param_values(tmp_path):
    with pytest.raises(ConfigError, match="unknown setting"):
        read_carmen_log(_write(tmp_path, _basic_log()), {"max_rang": 3})
    with pytest.raises(ConfigError, match="max_range"):
        CarmenOptions(max_range=-1.0)
    lines = ["PARAM robot_front_laser_max abc x 0", *_basic_log()]
    with pytest.raises(DatasetFormatError, match="robot_front_laser_max") as info:
        read_carmen_log(_write(tmp_path, lines, "p.log"))
    assert info.value.line == 1
    with pytest.raises(DatasetFormatError, match="no FLASER"):
        read_carmen_log(_write(tmp_path, HEADER, "e.log"))


def test_out_of_order_time_stamps_are_repaired_in_file_order(tmp_path):
    lines = [_flaser(_ranges(), (0, 0, 0), t) for t in (1.0, 2.0, 1.5, 3.0)]
    ds = read_carmen_log(_write(tmp_path, lines))
    assert ds.truth.times is not None
    # 1.5 goes back: the longest increasing run 1, 2, 3 keeps its stamps and the third
    # scan is placed between its neighbours in the file.
    np.testing.assert_allclose(ds.truth.times, [1.0, 2.0, 2.5, 3.0])
    assert ds.metadata["timestamps_repaired"] == 1
    assert ds.reading is not None and dict(ds.reading.repaired) == {"stamps out of order": 1}


def test_odometry_noise_is_known_and_seeded(tmp_path):
    # Steps of about 1 m (so the noisy translation never turns negative, which would flip the
    # decomposition into rot1/trans/rot2) along a wandering heading.
    rng = np.random.default_rng(7)
    heading = np.cumsum(rng.normal(0.0, 0.3, 2001))
    step = rng.uniform(0.8, 1.2, 2001)
    poses = np.stack(
        [np.cumsum(step * np.cos(heading)), np.cumsum(step * np.sin(heading)), heading], axis=1
    )
    lines = [_flaser(_ranges(), tuple(p), float(k)) for k, p in enumerate(poses)]
    path = _write(tmp_path, lines)
    opts = {"odometry_sigma_trans": 0.03, "odometry_sigma_rot_deg": 2.0}
    ds = read_carmen_log(path, opts, seed=11)
    again = read_carmen_log(path, opts, seed=11)
    other = read_carmen_log(path, opts, seed=12)
    odo = np.array([ev.pose for ev in ds.events if isinstance(ev, Odometry)])
    odo2 = np.array([ev.pose for ev in again.events if isinstance(ev, Odometry)])
    odo3 = np.array([ev.pose for ev in other.events if isinstance(ev, Odometry)])
    np.testing.assert_array_equal(odo, odo2)
    assert not np.allclose(odo, odo3)
    # The step noise has exactly the MotionSpec's covariance (2000 steps: std within 5 %).
    assert ds.truth.poses is not None and ds.motion is not None
    err = odometry_control(odo[:-1], odo[1:]) - odometry_control(
        ds.truth.poses[:-1], ds.truth.poses[1:]
    )
    err[:, [0, 2]] = (err[:, [0, 2]] + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(err.std(axis=0), np.sqrt(np.diag(ds.motion.noise_cov)), rtol=0.05)
    np.testing.assert_allclose(np.sqrt(np.diag(ds.motion.noise_cov)),
                               [np.deg2rad(2.0), 0.03, np.deg2rad(2.0)])  # fmt: skip


# --------------------------------------------------------------------------------------------
# DP-SLAM
# --------------------------------------------------------------------------------------------


def _dp_laser(n: int = 181, first: float = 0.5) -> str:
    return f"Laser {n} " + " ".join(f"{first + 0.01 * i:.6f}" for i in range(n))


def test_dpslam_hand_log(tmp_path):
    lines = [
        "Odometry 1.0 2.0 0.5",
        _dp_laser(),
        "Odometry 1.1 2.0 0.6",
        _dp_laser(first=8.0),
    ]
    ds = read_dpslam_log(_write(tmp_path, lines, "d.log"), {"scan_period": 0.5})
    assert ds.counts() == {"Odometry": 2, "LaserScan": 2}
    assert not ds.truth.has_trajectory
    odo = [ev for ev in ds.events if isinstance(ev, Odometry)]
    np.testing.assert_allclose(odo[1].pose, [1.1, 2.0, 0.6])
    assert odo[1].t == 0.5
    scans = [ev for ev in ds.events if isinstance(ev, LaserScan)]
    assert ds.laser is not None and ds.laser.n_beams == 181 and ds.laser.max_range == 8.183
    # 8.0 + 0.01 i passes 8.183 at i = 19 (8.19): from there on "no return".
    assert np.count_nonzero(scans[1].ranges == 8.183) == 181 - 19
    np.testing.assert_allclose(np.rad2deg(ds.laser.beam_angles[[0, 180]]), [-90, 90])


@pytest.mark.parametrize(
    ("lines", "message", "line"),
    [
        (["Odometry 1 2 3", _dp_laser(180)], "180 beams disagree", 2),
        (["Odometry 1 2", _dp_laser()], "three finite numbers", 1),
        ([_dp_laser()], "no Odometry line", 1),
        (["Odometry 1 2 3", _dp_laser().replace("0.510000", "nan")], "finite", 2),
        (["Odometry 1 2 3", _dp_laser().rsplit(" ", 1)[0]], "expected 181 numbers", 2),
        (["Odometry 1 2 3", "Sonar 1 2"], "unknown message", 2),
    ],
)
def test_dpslam_errors(tmp_path, lines, message, line):
    path = _write(tmp_path, lines, "d.log")
    with pytest.raises(DatasetFormatError, match=message) as info:
        read_dpslam_log(path)
    assert info.value.line == line


def test_dpslam_lenient(tmp_path):
    lines = ["Odometry 1 2 3", _dp_laser(180), "Odometry 1 2 3", _dp_laser()]
    ds = read_dpslam_log(_write(tmp_path, lines, "d.log"), {"lenient": True})
    assert ds.counts()["LaserScan"] == 1
    assert ds.metadata["skipped_lines"]["count"] == 1
    assert ds.metadata["skipped_lines"]["first"][0]["line"] == 2


# --------------------------------------------------------------------------------------------
# the real logs
# --------------------------------------------------------------------------------------------


@pytest.mark.realdata
def test_intel_log(data_root):
    ds = load_intel({}, seed=0, data_root=data_root)
    assert ds.name == "intel"
    assert ds.counts() == {"Odometry": 910, "LaserScan": 910}
    assert ds.laser is not None and ds.laser.n_beams == 180 and ds.laser.max_range == 80.0
    scan = next(ev for ev in ds.events if isinstance(ev, LaserScan))
    np.testing.assert_allclose(scan.ranges[[0, 1, 2, 179]], [1.09, 1.08, 1.08, 1.23])
    assert scan.t == 32.9068
    assert ds.truth.poses is not None and ds.truth.times is not None
    np.testing.assert_allclose(ds.truth.poses[0], [0.600266, -0.0320327, -0.354665])
    np.testing.assert_allclose(ds.truth.poses[-1], [-0.596494, -0.101202, 0.0119294])
    assert ds.truth.times[-1] == 2683.77
    assert np.all(np.diff(ds.truth.times) > 0)
    md = ds.metadata
    assert md["max_range_readings"] == 4172  # the 81.83 m readings
    assert md["timestamps_repaired"] == 4
    assert md["odom_lines_ignored"] == 14541
    assert md["skipped_lines"]["count"] == 0


@pytest.mark.realdata
def test_aces_log(data_root):
    ds = load_aces({}, seed=0, data_root=data_root)
    assert ds.counts() == {"Odometry": 440, "LaserScan": 440}
    assert ds.laser is not None and ds.laser.max_range == 50.0  # the log's clip value
    assert ds.metadata["max_range_readings"] == 620
    scan = next(ev for ev in ds.events if isinstance(ev, LaserScan))
    np.testing.assert_allclose(scan.ranges[[0, 1, 2, 179]], [6.66, 6.86, 7.16, 1.64])
    assert ds.truth.poses is not None
    np.testing.assert_allclose(ds.truth.poses[0], [0.89706, -0.180771, -0.454003])


@pytest.mark.realdata
def test_freiburg079_log(data_root):
    ds = load_freiburg079({}, seed=0, data_root=data_root)
    assert ds.counts() == {"Odometry": 4791, "LaserScan": 4791}
    assert ds.laser is not None and ds.laser.n_beams == 360
    assert ds.metadata["angular_resolution_deg"] == 0.5  # PARAM laser_front_laser_resolution
    assert ds.laser.max_range == 80.99  # PARAM robot_front_laser_max
    assert ds.metadata["max_range_readings"] == 36004  # the 81.91 m readings
    scan = next(ev for ev in ds.events if isinstance(ev, LaserScan))
    np.testing.assert_allclose(scan.ranges[[0, 1, 2, 359]], [1.65, 1.66, 1.63, 1.0])
    assert ds.truth.poses is not None
    np.testing.assert_allclose(ds.truth.poses[0], [0.00123601, -0.00106807, 2.85e-05])


@pytest.mark.realdata
def test_loop5_log(data_root):
    ds = load_loop5({}, seed=0, data_root=data_root)
    assert ds.counts() == {"Odometry": 551, "LaserScan": 551}
    assert not ds.truth.has_trajectory
    odo = next(ev for ev in ds.events if isinstance(ev, Odometry))
    np.testing.assert_allclose(odo.pose, [-2.424026, 4.800517, 2.590948])
    scan = next(ev for ev in ds.events if isinstance(ev, LaserScan))
    np.testing.assert_allclose(scan.ranges[:3], [0.642, 0.645, 0.645])
    assert ds.metadata["max_range_readings"] == 6726  # SICK 8 m mode codes >= 8.183 m


def test_corrupt_gzip_bodies_are_format_errors(tmp_path):
    """Every single-byte flip inside the compressed body of a gzipped log is either read (a
    flip the checksum cannot see does not exist: gzip's CRC-32 sees all) or refused as a
    DatasetFormatError naming the file — never a raw zlib.error."""
    good = _write(tmp_path, _basic_log(), gz=True).read_bytes()
    for k in range(12, len(good) - 8, max(1, (len(good) - 20) // 40)):
        bad = bytearray(good)
        bad[k] ^= 0xFF
        path = tmp_path / f"flip{k}.log.gz"
        path.write_bytes(bytes(bad))
        with pytest.raises(DatasetFormatError) as info:
            read_carmen_log(path)
        assert str(path) in str(info.value)


def test_line_numbers_count_newlines_only_and_digits_are_ascii(tmp_path):
    lines = _basic_log()
    lines.insert(2, "# a comment with a form feed \x0c and a line separator \u2028 in it")
    lines[4] = lines[4].replace(" 1.0 2.0 0.5 ", " 1.0 2.0 x ", 1)  # the first FLASER
    with pytest.raises(DatasetFormatError, match=r"log\.log:5:"):
        read_carmen_log(_write(tmp_path, lines))
    arabic = _basic_log()
    arabic[3] = arabic[3].replace(" 1.0 2.0 0.5 ", " ١ 2.0 0.5 ", 1)
    with pytest.raises(DatasetFormatError, match=r"log\.log:4:"):
        read_carmen_log(_write(tmp_path, arabic))


@pytest.mark.parametrize(
    "param",
    ["PARAM laser_front_laser_resolution 90 host 0", "PARAM laser_front_laser_fov 1000 host 0"],
)
def test_impossible_declared_beam_geometry_is_refused(tmp_path, param):
    """90° steps on a 180-beam log would span 16,110°; a 1000° field of view is no laser."""
    lines = [param, _flaser(_ranges(), (0.0, 0.0, 0.0), 1.0)]
    with pytest.raises(DatasetFormatError):
        read_carmen_log(_write(tmp_path, lines))
