"""Real logs' quirks are read, repaired and counted: stamps, the field of view's unit, the
reader chosen by content, the share a lenient read may drop, and the eleven corrected
CARMEN logs of the shared data read by path."""

from __future__ import annotations

import gzip
import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.datasets.carmen import read_carmen_log
from slamkit.datasets.files import laser_log_format, load_data, load_file
from slamkit.datasets.reading import ReadingSummary, check_dropped_share
from slamkit.datasets.stamps import RESTAMP_REASON, repair_stamps
from slamkit.datasets.stream import LaserScan
from slamkit.errors import ConfigError, DatasetFormatError
from slamkit.io import read_tum

runner = CliRunner()


# ------------------------------------------------------------------------------------------
# stamps
# ------------------------------------------------------------------------------------------


def test_increasing_stamps_pass_through_untouched():
    t = np.array([0.5, 1.25, 7.0])
    out, repair = repair_stamps(t)
    np.testing.assert_array_equal(out, t)
    assert repair.counts == {} and not repair.restamped


def test_zero_stamps_between_good_ones_are_interpolated_by_line():
    out, repair = repair_stamps(np.array([10.0, 0.0, 12.0, 13.0, 0.0, 15.0]))
    np.testing.assert_allclose(out, [10.0, 11.0, 12.0, 13.0, 14.0, 15.0])
    assert repair.counts == {"zero or negative stamps": 2}


def test_a_stamp_that_jumps_ahead_costs_only_itself():
    # One stamp far in the future must not push the rest out of the increasing run.
    out, repair = repair_stamps(np.array([1.0, 2.0, 900.0, 4.0, 5.0, 6.0]))
    np.testing.assert_allclose(out, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    assert repair.counts == {"stamps out of order": 1}


def test_implausible_and_non_finite_stamps_are_repaired():
    out, repair = repair_stamps(np.array([1.0, 2.0, 1e308, math.nan, 5.0]))
    np.testing.assert_allclose(out, [1.0, 2.0, 3.0, 4.0, 5.0])
    assert repair.counts == {"stamps not a plausible time": 2}


def test_low_precision_stamps_spread_around_each_printed_value():
    # "1.13486e+09" printed for three scans, then "1.13487e+09" for three: each run is one
    # rounded time, so its middle line keeps the value and the others spread at the period.
    t = np.array([1134860000.0] * 3 + [1134870000.0] * 3)
    out, repair = repair_stamps(t)
    assert np.all(np.diff(out) > 0)
    assert out[1] == 1134860000.0 and out[4] == 1134870000.0
    np.testing.assert_allclose(np.diff(out), 10000.0 / 3.0)
    assert repair.counts == {"repeated stamps": 6} and not repair.restamped


@pytest.mark.parametrize("stamps", [[0.0] * 5, [1.01893e9] * 5, [5.0, 4.0, 3.0, 2.0, 1.0]])
def test_stamps_without_timing_are_re_made_from_the_line_order(stamps):
    out, repair = repair_stamps(np.array(stamps), nominal_period=2.0)
    np.testing.assert_allclose(np.diff(out), 2.0)
    assert repair.restamped and repair.counts == {RESTAMP_REASON: 5}


# ------------------------------------------------------------------------------------------
# corrected CARMEN logs written by hand
# ------------------------------------------------------------------------------------------


def _flaser(n: int, k: int, t: float) -> str:
    ranges = " ".join(f"{1.0 + 0.01 * i:g}" for i in range(n))
    x = 0.1 * k
    return f"FLASER {n} {ranges} {x} 0 0 {x} 0 0 {t} host {t}"


def _log(tmp_path, lines, name="log.log"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_field_of_view_in_radians_is_told_apart_by_its_value(tmp_path):
    scans = [_flaser(181, k, 1.0 + k) for k in range(3)]
    path = _log(tmp_path, ["PARAM laser_front_laser_fov 3.14159265 nohost 0", *scans])
    ds = read_carmen_log(path)
    assert ds.laser is not None
    np.testing.assert_allclose(np.rad2deg(ds.laser.beam_angles[[0, 1, 180]]), [-90, -89, 90])
    assert ds.reading is not None
    assert ds.reading.notes == ("PARAM laser_front_laser_fov 3.14159 read as radians (180° at 1°)",)
    degrees = read_carmen_log(
        _log(tmp_path, ["PARAM laser_front_laser_fov 180 h 0", *scans], "d.log")
    )
    assert degrees.laser is not None and degrees.reading is not None
    np.testing.assert_allclose(degrees.laser.beam_angles, ds.laser.beam_angles, atol=1e-8)
    assert degrees.reading.notes == ()


def test_the_frontlaser_spelling_of_the_resolution_is_read(tmp_path):
    # As in fhw-corrected.log: "PARAM laser_frontlaser_resolution 1 0.0 nohost 0".
    scans = [_flaser(180, k, 1.0 + k) for k in range(3)]
    path = _log(tmp_path, ["PARAM laser_frontlaser_resolution 0.5 0.0 nohost 0", *scans])
    ds = read_carmen_log(path)
    assert ds.laser is not None and ds.metadata["geometry_from"] == "PARAM"
    np.testing.assert_allclose(np.rad2deg(ds.laser.beam_angles[[0, 179]]), [-45.0, 44.5])


def test_a_lenient_read_that_keeps_two_scans_of_406_is_an_error(tmp_path):
    scans = [_flaser(180, k, 1.0 + k) for k in range(406)]
    broken = [s.replace("FLASER 180 1 ", "FLASER 180 x ") for s in scans[2:]]
    path = _log(tmp_path, [*scans[:2], *broken])
    with pytest.raises(DatasetFormatError, match=r"log.log: 404 of 406 scans could not be used"):
        read_carmen_log(path, {"lenient": True})
    few = _log(tmp_path, [*scans[:400], *broken[:2]], "few.log")
    ds = read_carmen_log(few, {"lenient": True})
    assert ds.reading is not None and (ds.reading.records, ds.reading.used) == (402, 400)
    assert dict(ds.reading.dropped) == {"FLASER: a field is not a number": 2}


def test_check_dropped_share_allows_a_few_and_ten_percent():
    check_dropped_share("a.log", 3, 2)
    check_dropped_share("a.log", 100, 10)
    with pytest.raises(DatasetFormatError, match=r"a\.log: 11 of 100 scans"):
        check_dropped_share("a.log", 100, 11)


def test_the_summary_prints_one_line_or_two():
    clean = ReadingSummary("a.log", 5, 5)
    assert clean.clean and clean.lines() == ["read a.log: 5 of 5 scans"]
    quirky = ReadingSummary("a.log", 5, 4, dropped={"bad": 1}, repaired={"stamps x": 2})
    assert quirky.lines() == ["read a.log: 4 of 5 scans; dropped 1 bad", "  repaired 2 stamps x"]


# ------------------------------------------------------------------------------------------
# the reader is chosen by the content
# ------------------------------------------------------------------------------------------


def test_the_reader_is_chosen_by_content(tmp_path):
    scans = [_flaser(180, k, 1.0 + k) for k in range(3)]
    raw = _log(tmp_path, scans, "raw.log")
    corrected = _log(tmp_path, [s + "\nNEFF 30" for s in scans], "run.log")
    dpslam = tmp_path / "loop.log.gz"
    laser = "Laser 181 " + " ".join(["2.0"] * 181)
    dpslam.write_bytes(gzip.compress(f"Odometry 0 0 0\n{laser}\n".encode()))
    assert laser_log_format(raw) == "carmen-raw"
    assert laser_log_format(corrected) == "carmen-corrected"
    assert laser_log_format(_log(tmp_path, scans, "x-corrected.log")) == "carmen-corrected"
    assert laser_log_format(dpslam) == "dpslam"
    ds = load_file(corrected, seed=3)
    assert ds.provenance.reader == "carmen-corrected" and ds.truth.poses is not None
    assert load_file(dpslam).provenance.reader == "dpslam"
    forced = load_file(corrected, {"reader": "carmen-raw"})
    assert forced.provenance.reader == "carmen-raw" and forced.truth.poses is None
    with pytest.raises(ConfigError, match="reader: expected one of"):
        load_file(corrected, {"reader": "carmen"})


# ------------------------------------------------------------------------------------------
# the eleven corrected logs of the shared data
# ------------------------------------------------------------------------------------------

CORRECTED = {  # name: (scans, beams, what reading them repairs)
    "acapulco": (861, 181, None),
    "aces": (440, 180, None),
    "belgioioso": (395, 361, "restamped"),
    "edmonton": (340, 180, None),
    "fhw": (488, 180, None),
    "freiburg-079": (4791, 360, None),
    "freiburg-101": (292, 360, None),
    "freiburg-campus": (2008, 360, "restamped"),
    "intel": (910, 180, {"stamps out of order": 4}),
    "orebro": (237, 181, "restamped"),
    "seattle": (241, 361, None),
}


@pytest.mark.parametrize("name", sorted(CORRECTED))
def test_each_corrected_log_reads_by_path(data_root, name):
    path = data_root / "laser" / "corrected_carmen" / f"{name}-corrected.log.gz"
    ds = load_data(str(path))
    scans, beams, repair = CORRECTED[name]
    assert ds.provenance.reader == "carmen-corrected"
    assert ds.laser is not None and ds.laser.n_beams == beams
    np.testing.assert_allclose(
        np.rad2deg(ds.laser.beam_angles[[0, -1]]), [-90, 90 - 180 / beams * (beams % 2 == 0)]
    )
    times = np.array([e.t for e in ds.events if isinstance(e, LaserScan)])
    assert times.size == scans and np.all(np.diff(times) > 0)
    assert ds.truth.times is not None and ds.truth.times.size == scans
    assert ds.reading is not None and (ds.reading.records, ds.reading.used) == (scans, scans)
    assert dict(ds.reading.dropped) == {}
    if repair == "restamped":
        assert ds.reading.notes[-1].endswith("re-made from the line order, 1 s apart")
        np.testing.assert_allclose(np.diff(times), 1.0)
    elif repair is None:
        assert ds.reading.clean
    else:
        assert dict(ds.reading.repaired) == repair


def test_a_corrected_log_maps_and_writes_its_truth_from_the_command_line(data_root, tmp_path):
    path = data_root / "laser" / "corrected_carmen" / "orebro-corrected.log.gz"
    out = tmp_path / "run"
    res = runner.invoke(app, ["run", "occupancy-mapping", "--data", str(path), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "read orebro-corrected.log.gz: 237 of 237 scans" in res.output
    times, poses = read_tum(out / "groundtruth.tum")
    first = gzip.decompress(path.read_bytes()).decode().split("FLASER 181 ", 1)[1].split()
    np.testing.assert_allclose(poses[0, :2], [float(first[181]), float(first[182])])
    assert times.size == 237
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["reading"]["used"] == 237 and len(metrics["reading"]["notes"]) == 1
    mapped = tmp_path / "map"
    res = runner.invoke(app, ["map", "occupancy", "--data", str(path), "--out", str(mapped)])
    assert res.exit_code == 0, res.output
    quality = json.loads((mapped / "quality.json").read_text())
    assert quality["reading"]["records"] == 237 and quality["stats"]["scans_seen"] == 237
