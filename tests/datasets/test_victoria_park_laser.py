"""Victoria Park's raw laser (``victoria-park-laser``).

Synthetic tests (always run): the loader's conversions on tiny files written here (no
return, beam geometry and mounting, controls cut at scan times, ties, GPS columns, scans
outside the speed/steering samples) and its errors on malformed lines. Real-data tests
(skipped when the data folder is absent): counts and stamps, the no-return readings counted
independently from the file, and dead reckoning of the controls against the GPS and against
``victoria-park``, which holds the same odometry samples.
"""

from __future__ import annotations

import gzip
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import Control, Dataset, LaserScan, load_dataset
from slamkit.datasets.registry import dataset_available, get_dataset_entry
from slamkit.datasets.victoria_park import LASER_MAX_RANGE, LASER_OFFSET
from slamkit.datasets.victoria_park_laser import (
    DRS_FILE,
    N_BEAMS,
    RAW_GPS_FILE,
    SCANS_FILE,
    SENSORS_FILE,
    VICTORIA_PARK_LASER_FILES,
    load_victoria_park_laser,
)
from slamkit.errors import ConfigError, DatasetFormatError
from slamkit.eval.gps import gps_error
from slamkit.pipeline import Result, run


def _scans(ds: Dataset) -> list[LaserScan]:
    return [e for e in ds.events if isinstance(e, LaserScan)]


def _controls(ds: Dataset) -> list[Control]:
    return [e for e in ds.events if isinstance(e, Control)]


# ========================================================================= synthetic files
DRS_ROWS = ["1.000 0.000 0.0100", "1.025 2.000 0.1000", "1.050 2.000 0.1000",
            "1.075 2.000 -0.2000", "1.100 0.000 0.0000"]  # fmt: skip
GPS_ROWS = ["0.000 0.00 0.00", "1.001 1.00 2.00"]  # time north east
SCAN_TIMES = (0.990, 1.040, 1.075, 1.150)  # before, inside, at a sample, after


def _ranges() -> list[float]:
    r = [5.0] * N_BEAMS
    r[0], r[1], r[2], r[3], r[360] = 81.91, 81.87, 80.5, 79.99, 0.05
    return r


def _scan_line(t: float, ranges: Sequence[float]) -> str:
    return f"{t:.3f} " + " ".join(f"{x:.2f}" for x in ranges)


def _write(
    root: Path,
    scans: Sequence[str] | None = None,
    drs: Sequence[str] = DRS_ROWS,
    gps: Sequence[str] = GPS_ROWS,
    sensors: Sequence[str] | None = None,
) -> Path:
    """The four files under ``root``; ``sensors`` by default lists the others' lines in time
    order (GPS, DRS, laser at a tie)."""
    if scans is None:
        scans = [_scan_line(t, _ranges()) for t in SCAN_TIMES]
    if sensors is None:
        rows = [
            (float(line.split()[0]), k, i)
            for k, lines in ((1, gps), (2, drs), (3, scans))
            for i, line in enumerate(lines, start=1)
        ]
        sensors = [f"{t:.3f} {k} {i}" for t, k, i in sorted(rows)]
    for rel, lines in (
        (SCANS_FILE, ["# time_s range_0 ... range_360", *scans]),
        (DRS_FILE, drs),
        (RAW_GPS_FILE, gps),
        (SENSORS_FILE, sensors),
    ):
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        with gzip.open(path, "wt", encoding="utf-8") as fh:
            fh.write("\n".join(lines) + "\n")
    return root


def test_conversions_by_hand(tmp_path: Path) -> None:
    ds = load_victoria_park_laser({}, data_root=_write(tmp_path))
    # Beams: -90° .. +90° at 0.5°, the laser 3.78 m ahead and 0.5 m left of the rear axle.
    assert ds.laser is not None and ds.laser.n_beams == 361
    np.testing.assert_allclose(ds.laser.beam_angles[[0, 1, 180, 360]],
                               np.radians([-90.0, -89.5, 0.0, 90.0]), atol=1e-15)  # fmt: skip
    assert ds.laser.mounting == (*LASER_OFFSET, 0.0) and ds.laser.max_range == 80.0
    # No return: 80 m and beyond (the marker, an error code, 80.5 m) becomes max_range.
    scan = _scans(ds)[0]
    np.testing.assert_array_equal(scan.ranges[:5], [80.0, 80.0, 80.0, 79.99, 5.0])
    assert scan.ranges[360] == 0.05
    assert ds.metadata["no_return_readings"] == 12
    assert ds.metadata["no_return_marker_readings"] == ds.metadata["sick_error_code_readings"] == 4
    # Order: a scan at a sample's time follows the control that ends then; the interval
    # (1.025, 1.050] is cut at the scan at 1.040; the first and last scans, outside the
    # samples while the truck stands, are kept and counted.
    kinds = [(type(e).__name__[0], round(e.t, 3)) for e in ds.events]
    assert kinds == [("L", 0.99), ("C", 1.025), ("C", 1.04), ("L", 1.04), ("C", 1.05),
                     ("C", 1.075), ("L", 1.075), ("C", 1.1), ("L", 1.15)]  # fmt: skip
    ctrl = _controls(ds)
    np.testing.assert_allclose([c.dt for c in ctrl], [0.025, 0.015, 0.010, 0.025, 0.025])
    np.testing.assert_array_equal(ctrl[1].u, [2.0, 0.1])
    np.testing.assert_array_equal(ctrl[2].u, [2.0, 0.1])
    np.testing.assert_array_equal(ctrl[4].u, [2.0, -0.2])
    # GPS: the file's columns are north, east; kept as (east, north).
    assert ds.truth.positions is not None
    np.testing.assert_array_equal(ds.truth.positions, [[0.0, 0.0], [2.0, 1.0]])
    assert ds.reading is not None and ds.reading.used == ds.reading.records == 4
    assert ds.reading.repaired == {"outside the speed/steering samples, truck standing: kept": 2}
    assert not ds.reading.dropped


def test_scans_outside_samples_dropped_when_moving(tmp_path: Path) -> None:
    drs = ["1.000 1.000 0.0", *DRS_ROWS[1:]]  # moving at the first sample
    times = [0.99] + [1.001 + 0.002 * i for i in range(10)]
    scans = [_scan_line(t, _ranges()) for t in times]
    ds = load_victoria_park_laser({}, data_root=_write(tmp_path, scans=scans, drs=drs))
    assert ds.reading is not None and ds.reading.used == 10 and ds.reading.records == 11
    assert ds.reading.dropped == {"before the first speed/steering sample, truck moving": 1}
    # More than 10% of the scans dropped is an error, not a result.
    few = [_scan_line(t, _ranges()) for t in (0.97, 0.98, 0.99, 1.01)]
    with pytest.raises(DatasetFormatError, match="3 of 4 scans"):
        load_victoria_park_laser({}, data_root=_write(tmp_path / "b", scans=few, drs=drs))


def test_max_duration(tmp_path: Path) -> None:
    ds = load_victoria_park_laser({"max_duration_s": 0.05}, data_root=_write(tmp_path))
    assert ds.end_time == 1.05 and ds.counts() == {"LaserScan": 2, "Control": 3}
    assert ds.truth.position_times is not None and ds.truth.position_times.size == 2
    with pytest.raises(ConfigError, match="max_duration_s"):
        load_victoria_park_laser({"max_duration_s": 0.0}, data_root=tmp_path)


def test_malformed_line_names_file_and_line(tmp_path: Path) -> None:
    short = _scan_line(1.04, _ranges()[:-1])  # 360 ranges
    scans = [_scan_line(0.99, _ranges()), short]
    with pytest.raises(DatasetFormatError, match="expected 362 columns, got 361") as err:
        load_victoria_park_laser({}, data_root=_write(tmp_path / "a", scans=scans))
    assert err.value.path is not None and err.value.path.name == "laser.txt.gz"
    assert err.value.line == 3  # after the header line and the first scan

    negative = _ranges()
    negative[7] = -0.5
    scans = [_scan_line(0.99, _ranges()), _scan_line(1.04, negative)]
    with pytest.raises(DatasetFormatError, match="beam 7: expected a range >= 0") as err:
        load_victoria_park_laser({}, data_root=_write(tmp_path / "b", scans=scans))
    assert err.value.line == 3

    drs = [*DRS_ROWS[:2], "1.050 fast 0.1", *DRS_ROWS[3:]]
    with pytest.raises(DatasetFormatError, match="column 2: expected a number") as err:
        load_victoria_park_laser({}, data_root=_write(tmp_path / "c", drs=drs))
    assert err.value.path is not None and err.value.path.name == "drs.txt.gz"
    assert err.value.line == 3

    drs = [*DRS_ROWS[:2], "1.020 2.0 0.1", *DRS_ROWS[3:]]
    with pytest.raises(DatasetFormatError, match="expected increasing times") as err:
        load_victoria_park_laser({}, data_root=_write(tmp_path / "d", drs=drs, sensors=["0 1 1"]))
    assert err.value.line == 3


def test_sensors_manager_must_match_the_files(tmp_path: Path) -> None:
    root = _write(tmp_path / "a")
    lines = gzip.decompress((root / SENSORS_FILE).read_bytes()).decode().splitlines()
    assert lines[2] == "1.000 2 1"
    lines[2] = "1.000 4 1"  # an unknown sensor
    _write(tmp_path / "a", sensors=lines)
    with pytest.raises(DatasetFormatError, match="expected sensor 1") as err:
        load_victoria_park_laser({}, data_root=root)
    assert err.value.path is not None and err.value.path.name == "sensors_manager.txt.gz"
    assert err.value.line == 3
    with pytest.raises(DatasetFormatError, match=r"lists 0 GPS readings, gps\.txt\.gz holds 2"):
        load_victoria_park_laser({}, data_root=_write(tmp_path / "b", sensors=["0.990 3 1"]))


# ============================================================================== real data
realdata = pytest.mark.realdata
RAW_DRS_RATIO, RAW_DRS_OFFSET = 0.94412, -0.00246  # victoria-park steering = a x + b


def _need(root: Path) -> None:
    missing = [f for f in VICTORIA_PARK_LASER_FILES if not (root / f).exists()]
    if missing:
        pytest.skip(f"Victoria Park raw laser not found under {root}: {', '.join(missing)}")


@pytest.fixture(scope="module")
def vpl(data_root: Path) -> tuple[Dataset, Result]:
    """The whole run through the registry, dead-reckoned by the registered estimator."""
    _need(data_root)
    ds = load_dataset("victoria-park-laser", data_root=data_root)
    return ds, run("dead-reckoning", ds)


@realdata
def test_counts_stamps_and_beams(vpl: tuple[Dataset, Result], data_root: Path) -> None:
    ds, _ = vpl
    assert ds.counts() == {"LaserScan": 7_230, "Control": 68_704}
    scans, ctrl = _scans(ds), _controls(ds)
    assert ds.laser is not None and ds.laser.n_beams == 361
    assert all(s.ranges.shape == (361,) for s in scans)
    np.testing.assert_allclose(ds.laser.beam_angles, np.radians(-90.0 + 0.5 * np.arange(361)),
                               atol=1e-15)  # fmt: skip
    assert ds.laser.beam_angles[0] == -np.pi / 2 and ds.laser.beam_angles[-1] == np.pi / 2
    assert (scans[0].t, scans[-1].t) == (0.852, 1545.182)
    assert (ctrl[0].t, ctrl[-1].t) == (0.998, 1545.023)
    assert ds.truth.position_times is not None and ds.truth.position_times.size == 948

    # The controls: every DRS sample but the last, held to the next one, cut at each scan
    # strictly inside an interval (scans at a sample's time, or outside the samples, cut none).
    drs = np.loadtxt(data_root / DRS_FILE)
    t_scan = np.array([s.t for s in scans])
    inside = (t_scan > drs[0, 0]) & (t_scan < drs[-1, 0]) & ~np.isin(t_scan, drs[:, 0])
    assert len(ctrl) == drs.shape[0] - 1 + int(inside.sum()) == 61_762 + 6_942
    assert sum(c.dt for c in ctrl) == pytest.approx(drs[-1, 0] - drs[0, 0], abs=1e-8)
    np.testing.assert_array_equal(ctrl[0].u, drs[0, 1:])  # sample 1, held until 0.998 s

    # No return, counted from the file itself: every reading >= 80 m is max_range, the rest
    # unchanged; of them 2,017,831 are the 81.91-m marker.
    raw = np.loadtxt(data_root / SCANS_FILE)[:, 1:]
    ranges = np.stack([s.ranges for s in scans])
    far = raw >= LASER_MAX_RANGE
    np.testing.assert_array_equal(ranges == ds.laser.max_range, far)
    np.testing.assert_array_equal(ranges[~far], raw[~far])
    assert int(far.sum()) == ds.metadata["no_return_readings"] == 2_166_414
    assert int((raw >= 81.91).sum()) == ds.metadata["no_return_marker_readings"] == 2_017_831
    assert ds.reading is not None and ds.reading.used == ds.reading.records == 7_230


@realdata
def test_dead_reckoning_against_gps(vpl: tuple[Dataset, Result]) -> None:
    """Over the first 60 s, dead reckoning fits the GPS (as east, north) with an RMSE of
    0.56 m under a rotation of 35.8° (the truck's initial heading in the GPS frame); aligned
    there, it ends 235.6 m from the last fix (``victoria-park``, the same samples with the
    ACFR steering calibration: 194.8 m) — the drift of dead reckoning over 1545 s: the truck
    ends 21.7 m from its start, dead reckoning 215.5 m. Over the whole run the RMSE is
    57.3 m. The GPS columns are north, east: over the first 200 s (the first 100 s are
    nearly straight) the fit is 2.62 m as (east, north) and 9.57 m as the file's order."""
    ds, res = vpl
    tg, xy = ds.truth.position_times, ds.truth.positions
    assert tg is not None and xy is not None
    first = tg <= 0.973 + 60.0
    e60 = gps_error(res.times, res.poses, tg[first], xy[first])
    assert e60.rmse < 0.6 and e60.count == 88
    assert np.degrees(e60.alignment.angle) == pytest.approx(35.8, abs=0.5)
    end = e60.alignment.apply_to_points(res.poses[-1:, :2])[0]
    assert np.hypot(*(end - xy[-1])) == pytest.approx(235.6, abs=1.0)
    assert gps_error(res.times, res.poses, tg, xy).rmse == pytest.approx(57.3, abs=0.5)
    w = tg <= 0.973 + 200.0
    assert gps_error(res.times, res.poses, tg[w], xy[w]).rmse < 3.0
    assert gps_error(res.times, res.poses, tg[w], xy[w][:, ::-1]).rmse > 9.0


@realdata
def test_same_motion_as_victoria_park(data_root: Path) -> None:
    """With the ACFR calibration of the steering applied, dead reckoning of these controls
    is that of ``victoria-park`` (its clock 20.967 s ahead): 2 cm apart after 100 s and 1.3 m
    after the whole run (1545 s; the controls are cut at other times, scans here and tree
    detections there). The loaders turn the same samples into the same motion."""
    _need(data_root)
    if not (data_root / "landmarks/victoria_park/original_acfr/aa3_dr.csv.gz").exists():
        pytest.skip(f"victoria-park data not found under {data_root}")
    opts = {"max_duration_s": 100.0}
    ds = load_dataset("victoria-park-laser", options=opts, data_root=data_root)
    calibrated = tuple(
        replace(e, u=np.array([e.u[0], RAW_DRS_RATIO * e.u[1] + RAW_DRS_OFFSET]))
        if isinstance(e, Control)
        else e
        for e in ds.events
    )
    ours = run("dead-reckoning", replace(ds, events=calibrated))
    theirs = run("dead-reckoning", load_dataset("victoria-park", options=opts, data_root=data_root))
    k = int(np.searchsorted(theirs.times, ours.times[-1] + 20.967 - 1e-6))
    assert theirs.times[k] == pytest.approx(ours.times[-1] + 20.967, abs=1e-6)
    np.testing.assert_allclose(ours.poses[-1, :2], theirs.poses[k, :2], atol=0.03)
    assert abs(ours.poses[-1, 2] - theirs.poses[k, 2]) < 1e-3


@realdata
def test_registry_and_window(data_root: Path) -> None:
    _need(data_root)
    entry = get_dataset_entry("victoria-park-laser")
    assert entry.kind == "real" and entry.files == VICTORIA_PARK_LASER_FILES
    assert dataset_available(entry, data_root)
    ds = load_dataset("victoria-park-laser", options={"max_duration_s": 10.0}, data_root=data_root)
    assert ds.name == "victoria-park-laser" and ds.end_time <= 0.973 + 10.0
    assert ds.metadata["cut_at_s"] == pytest.approx(10.973)
    assert ds.reading is not None and ds.reading.used == len(_scans(ds)) == 48
    assert ds.reading.lines()[0] == f"read {SCANS_FILE}: 48 of 7230 scans"
