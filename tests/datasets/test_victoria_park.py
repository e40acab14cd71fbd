"""Victoria Park loader and GPS scoring.

Synthetic tests (always run): the loader's conversions on tiny files written here, its errors
on malformed rows, and the GPS outlier rejection and alignment on tracks with injected jumps.
Real-data tests (skipped when the data folder is absent): counts, units, conventions checked
against the GPS and the tree clusters, and dead reckoning against the GPS.
"""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import pytest

from slamkit.app.presets import preset_for
from slamkit.datasets import Control, Dataset, LandmarkReadings, load_dataset
from slamkit.datasets.text import read_table
from slamkit.datasets.victoria_park import (
    DETECTIONS_FILE,
    GPS_FILE,
    LASER_OFFSET,
    ODOMETRY_FILE,
    VICTORIA_PARK_FILES,
    laser_to_vehicle,
    load_victoria_park,
)
from slamkit.errors import ConfigError, DatasetFormatError, InputError
from slamkit.eval.gps import GpsScoreConfig, gps_error, gps_outliers
from slamkit.geometry import pose2
from slamkit.models import Ackermann
from slamkit.pipeline import Result, run


def _readings(ds: Dataset) -> list[LandmarkReadings]:
    return [e for e in ds.events if isinstance(e, LandmarkReadings)]


def _controls(ds: Dataset) -> list[Control]:
    return [e for e in ds.events if isinstance(e, Control)]


# ========================================================================= synthetic files
ODO_ROWS = ["1000 0 0.01", "1025 2.0 0.1", "1050 2.0 0.1", "1075 2.0 -0.2", "1100 1.0 0"]
GPS_ROWS = ["990 5 6", "1040 5.1 6.0", "1090 5.2 6.1"]
DET_ROWS = [
    "1000 10.0 1.5707963267948966 0 0 7",  # straight ahead at the start
    "1035 5.0 0.0 0 0 3",  # to the right, inside the 2nd odometry interval
    "1035 4.0 3.141592653589793 0 0 7",  # to the left, same time
    "1075 8.0 1.0 0 0 -1",  # a poor feature: dropped
    "1080 3.0 2.0 0 0 3",
]


def _write(root: Path, odo=ODO_ROWS, gps=GPS_ROWS, det=DET_ROWS) -> Path:
    """The three files with the given rows (after a header line) under ``root``."""
    for rel, rows, header in (
        (ODOMETRY_FILE, odo, "# time_ms speed_m_s steering_rad"),
        (GPS_FILE, gps, "# timeGps_ms Lo_m La_m"),
        (DETECTIONS_FILE, det, "# time_ms range_m bearing_rad x_est y_est feature_index"),
    ):
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        text = "\n".join([header, *rows]) + "\n"
        if path.suffix == ".gz":
            with gzip.open(path, "wt", encoding="utf-8") as fh:
                fh.write(text)
        else:
            path.write_text(text)
    return root


def test_laser_to_vehicle_by_hand() -> None:
    a, b = LASER_OFFSET
    z = laser_to_vehicle(np.array([10.0, 5.0, 4.0]), np.array([np.pi / 2, 0.0, np.pi]))
    # ahead: (a + 10, b); right: (a, b - 5); left: (a, b + 4)
    expected = np.array([[a + 10.0, b], [a, b - 5.0], [a, b + 4.0]])
    np.testing.assert_allclose(z[:, 0], np.hypot(*expected.T), atol=1e-12)
    np.testing.assert_allclose(z[:, 1], np.arctan2(expected[:, 1], expected[:, 0]), atol=1e-12)


def test_synthetic_files_convert_units_and_conventions(tmp_path: Path) -> None:
    ds = load_victoria_park({}, data_root=_write(tmp_path))
    md = ds.metadata
    assert md["odometry_samples"] == 5 and md["detections_in_file"] == 5
    assert md["detections_kept"] == 4 and md["dropped"] == {
        "poor_feature": 1,
        "outside_odometry": 0,
    }
    assert md["reading_events"] == 3 and md["trees"] == 2
    # 4 odometry intervals; the detections at 1.035 s and 1.08 s cut the 2nd and the 4th.
    ctrl = _controls(ds)
    assert [c.t for c in ctrl] == [1.025, 1.035, 1.05, 1.075, 1.08, 1.1]
    np.testing.assert_allclose(
        [c.dt for c in ctrl], [0.025, 0.01, 0.015, 0.025, 0.005, 0.02], atol=1e-12
    )
    np.testing.assert_array_equal(
        [c.u for c in ctrl], [[0, 0.01], [2, 0.1], [2, 0.1], [2, 0.1], [2, -0.2], [2, -0.2]]
    )
    # Readings follow the control that ends at their time; the first one is at the start.
    kinds = [type(e).__name__[0] for e in ds.events]
    assert kinds == ["L", "C", "C", "L", "C", "C", "C", "L", "C"]
    reads = _readings(ds)
    assert [r.t for r in reads] == [1.0, 1.035, 1.08]
    np.testing.assert_allclose(
        reads[1].z, laser_to_vehicle(np.array([5.0, 4.0]), np.array([0.0, np.pi]))
    )
    assert all(np.all(r.ids == -1) for r in reads)
    assert [t.tolist() for t in ds.truth.reading_ids or ()] == [[7], [3, 7], [3]]
    # GPS: seconds, every fix, no heading.
    np.testing.assert_allclose(ds.truth.position_times, [0.99, 1.04, 1.09])
    np.testing.assert_allclose(ds.truth.positions, [[5, 6], [5.1, 6.0], [5.2, 6.1]])
    assert not ds.truth.has_trajectory and ds.summary()["ground_truth"]["positions"]
    # The model: rear-axle centre, wheelbase 2.83, encoder 0.76 m left.
    assert ds.motion is not None and ds.motion.model == Ackermann(2.83, (0.0, 0.0), 0.76)
    np.testing.assert_array_equal(ds.initial_pose, np.zeros(3))
    sensor = ds.landmark_sensor
    assert sensor is not None and sensor.kind == "range-bearing" and not sensor.identities
    np.testing.assert_allclose(np.diag(sensor.noise_cov), [0.1**2, 0.01**2])
    assert sensor.offset == (3.78, 0.5)  # the laser sees from here (FastSLAM's misses)
    # FastSLAM's measured settings are a preset of the app layer; EKF-SLAM has none.
    fs = {"measurement_cov_scale": 36.0, "motion_cov_scale": 0.5, "hit_weight": 3}
    for name in ("fastslam1", "fastslam2"):
        preset = preset_for(name, "victoria-park")
        assert preset is not None and dict(preset.settings) == fs
    assert preset_for("ekf-slam", "victoria-park") is None


def test_synthetic_options(tmp_path: Path) -> None:
    root = _write(tmp_path)
    ds = load_victoria_park({"identities": True, "max_duration_s": 0.05}, data_root=root)
    reads = _readings(ds)
    assert [r.t for r in reads] == [1.0, 1.035]  # cut at 1.05 s
    assert [r.ids.tolist() for r in reads] == [[7], [3, 7]]
    assert ds.landmark_sensor is not None and ds.landmark_sensor.identities
    assert ds.events[-1].t == 1.05 and ds.metadata["cut_at_s"] == 1.05
    np.testing.assert_allclose(ds.truth.position_times, [0.99, 1.04])
    ds = load_victoria_park({"split_at_readings": False, "steering_offset": 0.5}, data_root=root)
    ctrl = _controls(ds)
    assert [c.t for c in ctrl] == [1.025, 1.05, 1.075, 1.1]
    np.testing.assert_allclose([c.u[1] for c in ctrl], [0.51, 0.6, 0.6, 0.3])
    ds = load_victoria_park({"laser_offset": [0.0, 0.0]}, data_root=root)
    np.testing.assert_allclose(_readings(ds)[1].z, [[5.0, -np.pi / 2], [4.0, np.pi / 2]])
    with pytest.raises(ConfigError, match="unknown setting"):
        load_victoria_park({"max_seconds": 3}, data_root=root)
    with pytest.raises(ConfigError, match="max_duration_s"):
        load_victoria_park({"max_duration_s": 0}, data_root=root)


@pytest.mark.parametrize(
    "which,row,line,match",
    [
        ("odo", "1050 2.0", 4, "expected 3 columns"),
        ("odo", "1050 fast 0.1", 4, "column 2: expected a number"),
        ("odo", "1020 2.0 0.1", 4, "expected increasing times"),
        ("odo", "1050 2.0 1.6", 4, "not a steering angle"),
        ("gps", "1040 5.1 nan", 3, "finite"),
        ("gps", "980 5.1 6.0", 3, "expected increasing times"),
        ("det", "1035 -5.0 0.0 0 0 3", 3, "positive range"),
        ("det", "1035 5.0 3.5 0 0 3", 3, r"bearing in \[0, pi\]"),
        ("det", "1035 5.0 0.5 0 0 2.5", 3, "feature index"),
        ("det", "990 5.0 0.5 0 0 2", 3, "non-decreasing times"),
    ],
)
def test_malformed_rows_name_file_and_line(
    tmp_path: Path, which: str, row: str, line: int, match: str
) -> None:
    rows = {"odo": list(ODO_ROWS), "gps": list(GPS_ROWS), "det": list(DET_ROWS)}
    rows[which][line - 2] = row  # line 1 is the header
    root = _write(tmp_path, rows["odo"], rows["gps"], rows["det"])
    path = root / {"odo": ODOMETRY_FILE, "gps": GPS_FILE, "det": DETECTIONS_FILE}[which]
    with pytest.raises(DatasetFormatError, match=match) as err:
        load_victoria_park({}, data_root=root)
    assert err.value.path == path and err.value.line == line


# ============================================================================ GPS scoring
def _line_track() -> tuple[np.ndarray, np.ndarray]:
    """101 fixes over 20 s at 5 Hz along a straight line at 2 m/s."""
    t = np.round(np.arange(101) * 0.2, 10)
    return t, np.column_stack([2.0 * t, np.zeros_like(t)])


def test_gps_outliers_on_injected_jumps() -> None:
    t, xy = _line_track()
    gps = xy.copy()
    gps[30] += [0.0, 50.0]  # a spike: unreachable from every neighbour
    gps[60] += [0.0, 3.0]  # a local jump, 3 m > max_residual, reachable at top speed
    gps[80:82] += [0.0, 2.5]  # a two-fix excursion: found once each is judged without the other
    gps[90] += [0.0, 1.5]  # within max_residual: kept
    out = gps_outliers(t, gps)
    np.testing.assert_array_equal(np.flatnonzero(out.unreachable), [30])
    np.testing.assert_array_equal(np.flatnonzero(out.jump), [60, 80, 81])
    assert not out.isolated.any() and not out.unchecked.any()
    # Without the iteration the excursion shields itself: fix 80 sees fix 81 on its side.
    loose = gps_outliers(t, gps, GpsScoreConfig(max_residual=100.0, tolerance=100.0))
    assert not loose.rejected.any()


def test_gps_outliers_isolated_and_unchecked() -> None:
    t = np.array([0.0, 0.2, 0.4, 0.6, 0.8, 20.0, 40.0, 40.2])
    xy = np.column_stack([t, np.zeros_like(t)])
    xy[5] = [500.0, 0.0]  # alone after a dropout: nothing to judge it by
    out = gps_outliers(t, xy)
    np.testing.assert_array_equal(np.flatnonzero(out.isolated), [5])
    np.testing.assert_array_equal(np.flatnonzero(out.unchecked), [5, 6, 7])  # < 3 neighbours
    assert not out.rejected.any()
    # A lone neighbour pair that disagrees: each is unreachable from its only neighbour.
    xy[7] = [140.0, 0.0]
    np.testing.assert_array_equal(np.flatnonzero(gps_outliers(t, xy).unreachable), [6, 7])


def test_gps_error_rejects_outliers_and_aligns_exactly() -> None:
    t, xy = _line_track()
    gps = xy.copy()
    gps[30] += [0.0, 50.0]
    gps[60] += [0.0, 3.0]
    # The estimate: the true line in another frame (rotated 30°, shifted), sampled at 40 Hz
    # over 2–18 s, so 10 fixes at each end are outside it.
    te = np.linspace(2.0, 18.0, 641)
    frame = np.array([3.0, -4.0, np.pi / 6])
    est = pose2.compose(frame, np.column_stack([2.0 * te, 0 * te, 0 * te]))
    e = gps_error(te, est, t, gps)
    d = e.as_dict()
    assert d["fixes"] == 101 and d["used"] == 79 and d["rejected_outliers"] == 2
    assert d["outside_estimate"] == 20 and d["rejected_unreachable"] == 1
    assert e.rmse < 1e-9 and e.max < 1e-9
    np.testing.assert_allclose(e.alignment.angle, -np.pi / 6, atol=1e-12)
    json.dumps(d, allow_nan=False)
    # Kept, the two outliers spoil the score.
    keep_all = GpsScoreConfig(tolerance=1e3, max_residual=1e3)
    assert gps_error(te, est, t, gps, keep_all).rmse > 3.0
    # A gap in the estimate is not bridged: none of its samples lies in (5.1 s, 7.9 s).
    gap = (te < 5.1) | (te > 7.9)
    # Fixes 5.2 s ... 7.8 s: 14, of which the spike at 6 s is already out.
    assert gps_error(te[gap], est[gap], t, gps).count == 79 - 13


def _wiggly_track() -> tuple[np.ndarray, np.ndarray]:
    """Poses every 25 ms over 60 s at 2 m/s with a heading that swings ±0.8 rad (Euler)."""
    te = np.arange(2401) * 0.025
    th = 0.8 * np.sin(0.2 * te)
    step = 2.0 * 0.025 * np.column_stack([np.cos(th), np.sin(th)])
    xy = np.vstack([[0.0, 0.0], np.cumsum(step[:-1], axis=0)])
    return te, np.column_stack([xy, th])


def test_gps_error_antenna_offset_and_robust_alignment() -> None:
    te, est = _wiggly_track()
    every = np.arange(0, te.size, 8)  # GPS at 5 Hz, at estimate samples
    t = te[every]
    gps = pose2.transform_points(est[every], np.array([1.0, 0.5]))  # antenna 1 m ahead, 0.5 left
    cfg = GpsScoreConfig(antenna_offset=(1.0, 0.5))
    assert gps_error(te, est, t, gps, cfg).rmse < 1e-9
    assert gps_error(te, est, t, gps).median > 0.3  # the offset turns with the truck
    # A 10-s stretch shifted by 10 m between two 5-s dropouts: no GPS-only test sees it.
    keep = (t < 35.0) | ((t >= 40.0) & (t < 50.0)) | (t >= 55.0)
    t2, gps2 = t[keep], gps[keep].copy()
    gps2[(t2 >= 40.0) & (t2 < 50.0)] += [10.0, 0.0]
    assert not gps_outliers(t2, gps2).rejected.any()
    plain = gps_error(te, est, t2, gps2, cfg)
    robust = gps_error(te, est, t2, gps2, GpsScoreConfig(antenna_offset=(1.0, 0.5), robust=True))
    assert plain.median > 1.0 and robust.median < 0.05 and robust.max > 9.0


def test_gps_error_input_errors() -> None:
    t, xy = _line_track()
    with pytest.raises(InputError, match="usable GPS fixes"):
        gps_error([100.0, 101.0], np.zeros((2, 3)), t, xy)
    with pytest.raises(InputError, match="increasing"):
        gps_error([0.0, 1.0], np.zeros((2, 3)), t[::-1], xy)
    with pytest.raises(ConfigError, match="max_speed"):
        GpsScoreConfig(max_speed=0.0)


# ============================================================================== real data
realdata = pytest.mark.realdata


def _need(root: Path) -> None:
    missing = [f for f in VICTORIA_PARK_FILES if not (root / f).exists()]
    if missing:
        pytest.skip(f"Victoria Park data not found under {root}: {', '.join(missing)}")


@pytest.fixture(scope="module")
def vp(data_root: Path) -> Dataset:
    _need(data_root)
    return load_victoria_park({}, data_root=data_root)


@pytest.fixture(scope="module")
def vp60(data_root: Path) -> tuple[Dataset, Result]:
    """The first 60 s through the registry, dead-reckoned by the registered estimator."""
    _need(data_root)
    ds = load_dataset("victoria-park", options={"max_duration_s": 60.0}, data_root=data_root)
    return ds, run("dead-reckoning", ds)


@realdata
def test_counts(vp: Dataset) -> None:
    md = vp.metadata
    assert md["odometry_samples"] == 61_945 and md["odometry_samples_used"] == 61_944
    assert md["detections_in_file"] == md["detections_kept"] == 46_860
    assert md["trees"] == 299 and md["reading_events"] == 7_122
    assert md["dropped"] == {"poor_feature": 0, "outside_odometry": 0}
    assert md["controls"] == 61_944 + md["controls_added_by_splitting"] == 68_789
    assert vp.counts() == {"Control": 68_789, "LandmarkReadings": 7_122}
    assert md["gps_fixes"] == 4_466
    ids = np.concatenate(vp.truth.reading_ids or ())
    assert ids.size == 46_860 and np.unique(ids).size == 299 and ids.min() == 1
    assert all(np.all(r.ids == -1) for r in _readings(vp))


@realdata
def test_units_and_known_lines(vp: Dataset) -> None:
    ctrl = _controls(vp)
    assert ctrl[0].t == 21.965 and ctrl[-1].t == 1570.54
    np.testing.assert_allclose(sum(c.dt for c in ctrl), 1570.54 - 21.94, atol=1e-8)
    np.testing.assert_array_equal(ctrl[0].u, [0.0, -0.00347172])  # file line 2, held 25 ms
    assert vp.truth.position_times is not None and vp.truth.positions is not None
    assert vp.truth.position_times[0] == 20.967
    np.testing.assert_array_equal(vp.truth.positions[0], [-67.64927094, -41.71421779])
    first = _readings(vp)[0]
    assert first.t == 22.033 and first.z.shape == (8, 2)
    # At the first detection the truck has not moved: the SLSJF estimate of the first tree
    # (x_est, y_est of the file) is the reading's point in the vehicle frame — the laser
    # offset (3.78, 0.50) and the bearing reference (bearing - pi/2) are those of SLSJF.
    r, b = first.z[0]
    np.testing.assert_allclose(
        [r * np.cos(b), r * np.sin(b)], [19.62954354, -12.44962023], atol=1e-7
    )


@realdata
def test_steering_sign_and_handedness_agree_with_gps(vp60: tuple[Dataset, Result]) -> None:
    """Dead reckoning (steering > 0 = left) fits the GPS under a proper rotation: RMSE 2.05 m
    over the first 60 s, 12.8 m when mirrored. The rotation, 33°, is the truck's initial
    heading in the GPS frame (35.5° in other work on this data set)."""
    ds, res = vp60
    truth = ds.truth
    e = gps_error(res.times, res.poses, truth.position_times, truth.positions)
    assert e.rmse < 2.5 and e.count == 198
    assert np.degrees(e.alignment.angle) == pytest.approx(33.0, abs=1.0)
    mirrored = res.poses * np.array([1.0, -1.0, -1.0])
    assert gps_error(res.times, mirrored, truth.position_times, truth.positions).rmse > 10.0


def _tree_spread(res: Result, readings: list[LandmarkReadings], true_ids: tuple) -> float:
    """Median over trees seen 3+ times of the RMS distance of a tree's detections, placed
    through the dead-reckoned poses, from their centroid."""
    pts = []
    for ev in readings:
        k = int(np.searchsorted(res.times, ev.t, side="right")) - 1  # the pose after the event
        assert res.times[k] == ev.t
        r, b = ev.z[:, 0], ev.z[:, 1]
        pts.append(
            pose2.transform_points(res.poses[k], np.column_stack([r * np.cos(b), r * np.sin(b)]))
        )
    p, ids = np.concatenate(pts), np.concatenate(true_ids)
    _, inv, cnt = np.unique(ids, return_inverse=True, return_counts=True)
    centre = np.stack([np.bincount(inv, p[:, d]) / cnt for d in range(2)], axis=-1)
    per_tree = np.sqrt(np.bincount(inv, np.sum((p - centre[inv]) ** 2, axis=1)) / cnt)
    assert np.sum(cnt >= 3) == 66  # over the first 60 s
    return float(np.median(per_tree[cnt >= 3]))


@realdata
def test_detections_cluster_into_trees(vp60: tuple[Dataset, Result], data_root: Path) -> None:
    """Over the first 60 s (2557 detections, 66 trees seen 3+ times) the detections placed
    through dead reckoning lie 0.59 m (median RMS) from their tree's centroid; with the laser
    0.95 m ahead of the rear axle (``info.txt``) 0.88 m; with the bearings mirrored 12.3 m."""
    ds, res = vp60
    reads, ids = _readings(ds), ds.truth.reading_ids or ()
    assert sum(r.ids.size for r in reads) == 2557
    spread = _tree_spread(res, reads, ids)
    assert spread < 0.65
    # The same detections (read from the file in order) with other conventions.
    raw = read_table(data_root / DETECTIONS_FILE, 6).values[:2557]
    ends = np.cumsum([r.ids.size for r in reads])[:-1]

    def variant(bearing: np.ndarray, offset: tuple[float, float]) -> list[LandmarkReadings]:
        z = np.split(laser_to_vehicle(raw[:, 1], bearing, offset), ends)
        return [LandmarkReadings(r.t, zk, r.ids) for r, zk in zip(reads, z, strict=True)]

    np.testing.assert_allclose(
        np.concatenate([r.z for r in variant(raw[:, 2], LASER_OFFSET)]),
        np.concatenate([r.z for r in reads]),
    )
    assert _tree_spread(res, variant(raw[:, 2], (0.95, 0.5)), ids) > spread + 0.2
    assert _tree_spread(res, variant(np.pi - raw[:, 2], LASER_OFFSET), ids) > 10.0


@realdata
def test_window_and_registry(data_root: Path) -> None:
    _need(data_root)
    ds = load_dataset("victoria-park", options={"max_duration_s": 10.0}, data_root=data_root)
    assert ds.name == "victoria-park" and ds.end_time <= 21.94 + 10.0
    assert ds.truth.position_times is not None and ds.truth.position_times[-1] <= 31.94
    summary = json.loads(json.dumps(ds.summary()))
    assert summary["ground_truth"]["positions"] and summary["cut_at_s"] == 31.94


# ================================================== SLAM variants of the other landmark sets
@realdata
def test_mrclam_and_citytrees_give_the_map_only_as_truth(data_root: Path) -> None:
    """For SLAM, estimators must not receive the landmark map: ``mrclam1`` has the option
    ``landmarks_known=False``; ``citytrees10000`` never sets ``known_landmarks``."""
    from slamkit.datasets.isam_landmarks import CITYTREES_FILES
    from slamkit.datasets.mrclam import mrclam_files

    if not all((data_root / f).exists() for f in (*mrclam_files(), *CITYTREES_FILES)):
        pytest.skip(f"MRCLAM or cityTrees10000 data not found under {data_root}")
    opts = {"max_duration_s": 30.0}
    known = load_dataset("mrclam1", options=opts, data_root=data_root)
    slam = load_dataset("mrclam1", options={**opts, "landmarks_known": False}, data_root=data_root)
    assert known.known_landmarks is not None and slam.known_landmarks is None
    assert slam.truth.landmarks is not None and len(slam.truth.landmarks) == 15
    assert slam.counts() == known.counts()
    city = load_dataset("citytrees10000", data_root=data_root)
    assert city.known_landmarks is None and city.truth.landmarks is not None


def test_ground_truth_positions_and_reading_ids_are_checked(tmp_path: Path) -> None:
    import dataclasses

    from slamkit.datasets import GroundTruth
    from slamkit.errors import ShapeError

    with pytest.raises(InputError, match="go together"):
        GroundTruth(position_times=np.array([0.0, 1.0]))
    with pytest.raises(ShapeError, match="positions"):
        GroundTruth(position_times=np.array([0.0, 1.0]), positions=np.zeros((3, 2)))
    with pytest.raises(InputError, match="non-decreasing"):
        GroundTruth(position_times=np.array([1.0, 0.0]), positions=np.zeros((2, 2)))
    ds = load_victoria_park({}, data_root=_write(tmp_path))
    ids = ds.truth.reading_ids or ()
    assert ds.check_reading_ids().tolist() == np.concatenate(ids).tolist()
    # A truth that no longer matches the events is refused when the association is scored.
    short = dataclasses.replace(ds, truth=dataclasses.replace(ds.truth, reading_ids=ids[:2]))
    with pytest.raises(ShapeError, match="expected 3 arrays"):
        short.check_reading_ids()
    wrong = (ids[0], ids[1][:1], ids[2])
    bad = dataclasses.replace(ds, truth=dataclasses.replace(ds.truth, reading_ids=wrong))
    with pytest.raises(ShapeError, match="expected 2 ids, got 1"):
        bad.check_reading_ids()
