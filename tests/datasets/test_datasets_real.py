"""Real-data loaders: UTIAS MRCLAM (Dataset 1, Robot 1) and CMU Plaza 1.

Counts and known lines of the files, the conversion conventions, and the numbers measured on
the data that the loaders' docstrings quote (dead reckoning against the truth and against the
published dead-reckoned path, range residuals). Skipped when the data folder is absent.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import Control, Dataset, LandmarkReadings
from slamkit.datasets.mrclam import load_mrclam, mrclam_files
from slamkit.datasets.plaza import DRP_FILE, PLAZA1_FILES, RANGE_SCALE, load_plaza1
from slamkit.datasets.text import read_table
from slamkit.errors import ConfigError, DataNotFoundError, DatasetFormatError
from slamkit.eval import absolute_trajectory_error, associate
from slamkit.geometry import angle_diff, wrap_angle
from slamkit.models import UnicycleArc
from slamkit.pipeline import Result, run
from slamkit.pipeline.evaluate import evaluate

pytestmark = pytest.mark.realdata

MRCLAM_DIR = "landmarks/utias_mrclam/MRCLAM_Dataset1"


def _need(root: Path, files: tuple[str, ...]) -> None:
    missing = [f for f in files if not (root / f).exists()]
    if missing:
        pytest.skip(f"real data not found under {root}: {', '.join(missing)}")


def _readings(ds: Dataset) -> list[LandmarkReadings]:
    return [e for e in ds.events if isinstance(e, LandmarkReadings)]


def _controls(ds: Dataset) -> list[Control]:
    return [e for e in ds.events if isinstance(e, Control)]


# ============================================================================== MRCLAM
@pytest.fixture(scope="module")
def mrclam(data_root: Path) -> Dataset:
    _need(data_root, mrclam_files())
    return load_mrclam({}, seed=0, data_root=data_root)


def test_mrclam_counts(mrclam: Dataset) -> None:
    md = mrclam.metadata
    assert md["odometry_samples"] == 97_890
    assert md["controls"] == 97_889  # the last sample has no successor
    assert md["readings_in_file"] == 5_723
    assert md["readings_kept"] == 4_771
    assert md["dropped"] == {
        "robot": 952,
        "unknown_barcode": 0,
        "no_landmark_position": 0,
        "before_odometry": 0,
    }
    assert md["reading_events"] == 3_518
    assert mrclam.counts() == {"Control": 97_889, "LandmarkReadings": 3_518}
    assert sum(e.ids.size for e in _readings(mrclam)) == 4_771
    assert md["start_time_unix_s"] == pytest.approx(1_248_272_272.841, abs=1e-6)


def test_mrclam_maps_and_specs(mrclam: Dataset) -> None:
    world = mrclam.known_landmarks
    assert world is not None and len(world) == 15
    np.testing.assert_array_equal(np.sort(world.ids), np.arange(6, 21))
    np.testing.assert_allclose(world.position_of([6]), [[5.70928255, 4.96404466]])
    np.testing.assert_allclose(world.position_of([20]), [[2.09939861, -3.91527208]])
    assert mrclam.truth.landmarks is world
    assert not mrclam.truth.has_trajectory
    assert mrclam.initial_pose is None and mrclam.initial_cov is None
    assert mrclam.motion is not None and isinstance(mrclam.motion.model, UnicycleArc)
    np.testing.assert_allclose(mrclam.motion.noise_cov, np.diag([0.2**2, 0.2**2]))
    sensor = mrclam.landmark_sensor
    assert sensor is not None and sensor.kind == "range-bearing"
    np.testing.assert_allclose(sensor.noise_cov, np.diag([0.15**2, 0.035**2]))
    # Every kept reading is of a landmark (subjects 6-20), never of a robot (1-5).
    ids = np.concatenate([e.ids for e in _readings(mrclam)])
    assert ids.min() >= 6 and ids.max() <= 20 and np.unique(ids).size == 15


def test_mrclam_events_time_ordered(mrclam: Dataset) -> None:
    t = np.array([e.t for e in mrclam.events])
    assert t[0] == pytest.approx(0.011) and np.all(np.diff(t) >= 0)
    assert mrclam.end_time == pytest.approx(1490.478)
    # Controls first at equal stamps: a reading sees the motion up to its own time.
    for a, b in zip(mrclam.events[:-1], mrclam.events[1:], strict=True):
        if a.t == b.t:
            assert not (isinstance(a, LandmarkReadings) and isinstance(b, Control))
    # Readings are grouped by stamp: no two reading events share a time.
    rt = np.array([e.t for e in _readings(mrclam)])
    assert np.all(np.diff(rt) > 0)


def test_mrclam_known_lines(mrclam: Dataset) -> None:
    controls = _controls(mrclam)
    # Odometry lines 5 and 6: "1248272272.841 0.074 0.229", then ".852": the first command
    # holds over the 11 ms up to the second sample.
    first = controls[0]
    assert first.t == pytest.approx(0.011, abs=1e-9) and first.dt == pytest.approx(0.011)
    np.testing.assert_array_equal(first.u, [0.074, 0.229])
    # The last two lines "...763.309 0.060 0.000" and "...763.319 0.061 0.000".
    last = controls[-1]
    assert last.t == pytest.approx(1490.478) and last.dt == pytest.approx(0.010)
    np.testing.assert_array_equal(last.u, [0.060, 0.0])
    # dt is the time to the next sample, so the controls tile the run without overlap.
    assert sum(c.dt for c in controls) == pytest.approx(1490.478, abs=1e-6)

    by_time = {round(e.t, 6): e for e in _readings(mrclam)}
    # Measurement line 5 "1248272276.038 90 2.148 0.025": barcode 90 is subject 16.
    ev = by_time[3.197]
    np.testing.assert_array_equal(ev.ids, [16])
    np.testing.assert_allclose(ev.z, [[2.148, 0.025]])
    # Line 6 "1248272276.727 14 3.387 0.006": barcode 14 is robot 2, dropped.
    assert 3.886 not in by_time
    # Lines 843-846 share a stamp: barcodes 9, 16, 14 (robot 2), 25 -> subjects 13, 15, 12.
    ev = by_time[204.802]
    np.testing.assert_array_equal(ev.ids, [13, 15, 12])
    np.testing.assert_allclose(ev.z, [[1.726, -0.558], [4.247, -0.359], [2.037, 0.242]])


def test_mrclam_swaps_the_labels_of_subjects_11_and_17(mrclam: Dataset, data_root: Path) -> None:
    # Measurement line 29 "1248272284.671 18 2.876 0.301": barcode 18 is subject 11 in
    # Barcodes.dat, but the landmark seen is the one surveyed as subject 17 (the evidence is
    # in the loader's docstring and in test_localization_real.py). Line 78
    # "1248272301.588 61 5.062 0.069": barcode 61, subject 17, is landmark 11.
    md = mrclam.metadata["label_corrections"]
    assert md == {"applied": {"11": 17, "17": 11}, "readings_relabelled": 776}
    by_time = {round(e.t, 6): e for e in _readings(mrclam)}
    np.testing.assert_array_equal(by_time[11.83].ids, [16, 17])
    np.testing.assert_allclose(by_time[11.83].z[1], [2.876, 0.301])
    np.testing.assert_array_equal(by_time[28.747].ids, [11])
    raw = load_mrclam({"correct_labels": False}, seed=0, data_root=data_root)
    assert raw.metadata["label_corrections"] == {"applied": {}, "readings_relabelled": 0}
    raw_by_time = {round(e.t, 6): e for e in _readings(raw)}
    np.testing.assert_array_equal(raw_by_time[11.83].ids, [16, 11])
    np.testing.assert_array_equal(raw_by_time[28.747].ids, [17])
    # Only the labels change: same events, same readings.
    assert raw.counts() == mrclam.counts()
    swap = {11: 17, 17: 11}
    for a, b in zip(_readings(raw), _readings(mrclam), strict=True):
        assert [swap.get(int(i), int(i)) for i in a.ids] == b.ids.tolist()
        np.testing.assert_array_equal(a.z, b.z)


def test_mrclam_cut_and_options(data_root: Path) -> None:
    _need(data_root, mrclam_files())
    short = load_mrclam({"max_duration_s": 60.0, "sigma_range": 0.2}, seed=0, data_root=data_root)
    t = np.array([e.t for e in short.events])
    assert t.max() <= 60.0 and t.max() > 59.9
    assert short.metadata["cut_at_s"] == 60.0
    assert 0 < short.metadata["controls"] < 97_889
    assert short.landmark_sensor is not None
    assert short.landmark_sensor.noise_cov[0, 0] == pytest.approx(0.04)
    with pytest.raises(ConfigError, match="robot"):
        load_mrclam({"robot": 7}, seed=0, data_root=data_root)
    with pytest.raises(ConfigError, match="unknown setting"):
        load_mrclam({"robots": 1}, seed=0, data_root=data_root)
    with pytest.raises(DataNotFoundError, match="Robot4_Odometry"):
        load_mrclam({"robot": 4}, seed=0, data_root=data_root)


def test_mrclam_malformed_copy_names_file_and_line(data_root: Path, tmp_path: Path) -> None:
    _need(data_root, mrclam_files())
    folder = tmp_path / MRCLAM_DIR
    folder.mkdir(parents=True)
    for f in mrclam_files():
        shutil.copy(data_root / f, folder)
    meas = folder / "Robot1_Measurement.dat"
    lines = meas.read_text().splitlines()
    lines[9] = "1248272280.199 \t 14 \t 3.118"  # line 10 loses its bearing
    meas.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetFormatError) as err:
        load_mrclam({}, seed=0, data_root=tmp_path)
    assert err.value.path == meas and err.value.line == 10
    lines[9] = "1248272280.199 \t 14 \t -3.118 \t -0.070"  # a negative range
    meas.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetFormatError, match="positive range") as err:
        load_mrclam({}, seed=0, data_root=tmp_path)
    assert err.value.line == 10


# =============================================================================== Plaza
@pytest.fixture(scope="module")
def plaza(data_root: Path) -> Dataset:
    _need(data_root, PLAZA1_FILES)
    return load_plaza1({}, seed=0, data_root=data_root)


@pytest.fixture(scope="module")
def plaza_dead_reckoning(plaza: Dataset) -> Result:
    """slamkit's dead-reckoning estimator over the whole run (about 9 s)."""
    return run("dead-reckoning", plaza)


def test_plaza_counts(plaza: Dataset) -> None:
    md = plaza.metadata
    assert md["odometry_rows"] == 9_657
    assert md["readings_in_file"] == 3_529 and md["readings_kept"] == 3_529
    assert md["dropped"] == {"unknown_beacon": 0}
    assert md["reading_events"] == 3_526  # three stamps carry two readings each
    assert md["reading_time_jumps_back"] == 2
    assert md["senders"] == [2]
    # Every reading inside an odometry interval cuts it: 9657 rows + 3526 pieces.
    assert md["controls"] == 13_183 and md["controls_added_by_splitting"] == 3_526
    assert plaza.counts() == {"Control": 13_183, "LandmarkReadings": 3_526}
    beacons = plaza.known_landmarks
    assert beacons is not None
    assert sorted(beacons.ids.tolist()) == [0, 1, 5, 6]
    np.testing.assert_allclose(beacons.position_of([5]), [[-17.664893, 59.009181]])
    assert plaza.truth.landmarks is beacons
    ids = np.concatenate([e.ids for e in _readings(plaza)])
    assert dict(zip(*np.unique(ids, return_counts=True), strict=True)) == {
        0: 902,
        1: 893,
        5: 848,
        6: 886,
    }
    assert plaza.truth.times is not None and plaza.truth.times.size == 9_658
    sensor = plaza.landmark_sensor
    assert sensor is not None and sensor.kind == "range" and sensor.dim == 1
    assert sensor.noise_cov[0, 0] == pytest.approx(0.25)


def test_plaza_prior_is_first_true_pose(plaza: Dataset) -> None:
    assert plaza.initial_pose is not None and plaza.initial_cov is not None
    np.testing.assert_allclose(plaza.initial_pose, [0.0, 0.0, wrap_angle(4.222432)])
    np.testing.assert_allclose(np.diag(plaza.initial_cov), [0.05**2, 0.05**2, 0.02**2])
    assert plaza.start_time == pytest.approx(3856.857346)
    assert plaza.truth.poses is not None
    assert np.all((plaza.truth.poses[:, 2] >= -np.pi) & (plaza.truth.poses[:, 2] < np.pi))


def test_plaza_known_lines(plaza: Dataset, data_root: Path) -> None:
    t = np.array([e.t for e in plaza.events])
    assert np.all(np.diff(t) >= 0)
    controls = _controls(plaza)
    # DR line 1: "3857.0532019138336 2.3483858154428326e-004 -5.2000000000163027e-005",
    # spread over the time since the first true pose (3856.857346).
    first = controls[0]
    assert first.t == 3857.0532019138336
    assert first.dt == pytest.approx(3857.0532019138336 - 3856.857346)
    np.testing.assert_allclose(
        first.u * first.dt, [2.3483858154428326e-4, -5.2000000000163027e-5], rtol=1e-12
    )
    # TD line 1: "3858.0620000362396 2 5 6.5466007843625079e+001" (beacon 5), calibrated.
    ev = _readings(plaza)[0]
    assert ev.t == 3858.0620000362396
    np.testing.assert_array_equal(ev.ids, [5])
    np.testing.assert_allclose(ev.z, [[65.466007843625079 * RANGE_SCALE]])
    # A control ends exactly at every reading time, so readings see the pose of their time.
    ends = {c.t for c in controls}
    assert all(e.t in ends for e in _readings(plaza))
    # The pieces of the cut controls add up to the odometry increments of the file.
    dr = read_table(data_root / PLAZA1_FILES[0], 3).values
    total = np.sum([c.u * c.dt for c in controls], axis=0)
    np.testing.assert_allclose(total, dr[:, 1:].sum(axis=0), rtol=1e-10)


def test_plaza_without_splitting_and_cut(data_root: Path) -> None:
    _need(data_root, PLAZA1_FILES)
    whole = load_plaza1({"split_at_readings": False}, seed=0, data_root=data_root)
    assert whole.counts() == {"Control": 9_657, "LandmarkReadings": 3_526}
    short = load_plaza1({"max_duration_s": 100.0}, seed=0, data_root=data_root)
    t_end = 3856.857346 + 100.0
    assert short.end_time <= t_end and short.end_time > t_end - 0.3
    assert short.truth.times is not None and short.truth.times[-1] <= t_end
    assert short.metadata["odometry_rows_used"] < 9_657
    with pytest.raises(ConfigError, match="range_scale"):
        load_plaza1({"range_scale": 0.0}, seed=0, data_root=data_root)


@pytest.mark.slow
def test_plaza_dead_reckoning_against_published_path(
    plaza: Dataset, plaza_dead_reckoning: Result, data_root: Path
) -> None:
    """What of Plaza1_DRp.csv the conversion reproduces, and what nobody can.

    Its headings are theta_0 + cumsum(dtheta) and its steps are d long: both reproduced to
    round-off (the arc's chord is shorter than d by d dtheta² / 24 < 1e-4 m). Its positions
    are not: their direction of travel drifts from the heading column (measured: 42 m apart
    at worst), and they are ten times farther from the truth than dead reckoning here.
    """
    _need(data_root, (DRP_FILE,))
    drp = read_table(data_root / DRP_FILE, 4).values
    res = plaza_dead_reckoning
    # Each DRp row after the start has the time of its DR row (to 1e-6 s), where one of
    # our controls ends.
    ib, ia = associate(drp[:, 0], res.times, 1e-5)
    assert np.array_equal(ib, np.arange(1, drp.shape[0]))
    est, ref = res.poses[ia], drp[ib]
    np.testing.assert_allclose(angle_diff(est[:, 2], ref[:, 3]), 0.0, atol=1e-9)
    # Step lengths between consecutive DRp rows (skip the pieces cut by readings).
    pick = np.flatnonzero(np.diff(ib) == 1)
    ours = np.hypot(*np.diff(est[:, :2], axis=0)[pick].T)
    theirs = np.hypot(*np.diff(ref[:, 1:3], axis=0)[pick].T)
    turn = angle_diff(ref[pick + 1, 3], ref[pick, 3])
    assert pick.size > 9_600
    # The chord of an arc of length d turning by dtheta: d sin(dtheta/2) / (dtheta/2).
    np.testing.assert_allclose(ours, theirs * np.sinc(turn / (2 * np.pi)), rtol=0, atol=2e-8)
    assert np.abs(ours - theirs).max() < 2.5e-4
    # Positions: measured max 41.9 m apart.
    gap = np.hypot(*(est[:, :2] - ref[:, 1:3]).T)
    assert 35.0 < gap.max() < 50.0
    truth = plaza.truth
    assert truth.times is not None and truth.poses is not None
    ja, jb = associate(drp[:, 0], truth.times, 1e-3)
    published = absolute_trajectory_error(drp[ja, 1:], truth.poses[jb], align="none")
    assert published.rmse == pytest.approx(20.29, abs=0.1)


@pytest.mark.slow
def test_plaza_dead_reckoning_ate(plaza: Dataset, plaza_dead_reckoning: Result) -> None:
    """The baseline every estimator on Plaza 1 must beat (measured: ATE RMSE 1.935 m
    unaligned, 1.471 m SE(2)-aligned; final error 4.45 m after 1.86 km)."""
    ev = evaluate(plaza_dead_reckoning, plaza, max_dt=1e-3)
    m = ev.metrics
    assert m["ate_unaligned"]["rmse"] == pytest.approx(1.935, rel=0.05)
    assert m["ate_unaligned"]["max"] == pytest.approx(4.45, rel=0.05)
    assert m["ate"]["rmse"] == pytest.approx(1.471, rel=0.05)
    assert m["final_position_error"] == pytest.approx(4.45, rel=0.05)
    # The true headings are the odometry's own cumulative heading.
    assert m["ate_unaligned"]["heading_rmse"] < 1e-4


def _ranges_and_distances(ds: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """Every range reading and the distance from the true position (interpolated to the
    reading time) to its beacon."""
    assert ds.truth.times is not None and ds.truth.poses is not None
    assert ds.known_landmarks is not None
    evs = _readings(ds)
    t = np.concatenate([np.full(e.ids.size, e.t) for e in evs])
    z = np.concatenate([e.z[:, 0] for e in evs])
    b = ds.known_landmarks.position_of(np.concatenate([e.ids for e in evs]))
    x = np.interp(t, ds.truth.times, ds.truth.poses[:, 0])
    y = np.interp(t, ds.truth.times, ds.truth.poses[:, 1])
    return z, np.hypot(b[:, 0] - x, b[:, 1] - y)


def _robust(r: np.ndarray) -> tuple[float, float]:
    med = float(np.median(r))
    return med, 1.4826 * float(np.median(np.abs(r - med)))


def test_plaza_range_residuals(plaza: Dataset, data_root: Path) -> None:
    """Calibrated ranges against the true path (measured: median -0.003 m, MAD-sigma
    0.494 m, std 0.505 m, 13 of 3529 beyond 3 sigma, none beyond 2 m)."""
    z, d = _ranges_and_distances(plaza)
    r = z - d
    med, sigma = _robust(r)
    assert abs(med) < 0.02
    assert sigma == pytest.approx(0.494, abs=0.01)
    assert r.std() == pytest.approx(0.505, abs=0.01)
    outliers = np.abs(r - med) > 3 * sigma
    assert outliers.sum() == 13 and outliers.mean() < 0.005
    assert np.abs(r).max() < 2.0
    # As recorded (range_scale = 1): 7 % too long, median +2.84 m, MAD-sigma 1.22 m.
    raw = load_plaza1({"range_scale": 1.0}, seed=0, data_root=data_root)
    z_raw, d_raw = _ranges_and_distances(raw)
    np.testing.assert_allclose(z_raw * RANGE_SCALE, z, rtol=1e-12)
    med, sigma = _robust(z_raw - d_raw)
    assert med == pytest.approx(2.84, abs=0.01) and sigma == pytest.approx(1.22, abs=0.01)
    assert np.median(z_raw / d_raw) == pytest.approx(1.070, abs=0.002)


def test_pieces_cut_intervals_only_strictly_inside() -> None:
    from slamkit.datasets.plaza import cut_intervals

    t_start = np.array([0.0, 1.0, 2.0])
    t_end = np.array([1.0, 2.0, 3.0])
    # Before the first interval, on a boundary, twice inside the second, after the last.
    cuts = np.array([-1.0, 1.0, 1.25, 1.5, 2.5, 4.0])
    ends, dts, owner = cut_intervals(t_start, t_end, cuts)
    np.testing.assert_array_equal(ends, [1.0, 1.25, 1.5, 2.0, 2.5, 3.0])
    np.testing.assert_allclose(dts, [1.0, 0.25, 0.25, 0.5, 0.5, 0.5])
    np.testing.assert_array_equal(owner, [0, 1, 1, 1, 2, 2])


@pytest.mark.parametrize(
    "name,target,files",
    [
        ("mrclam1", "slamkit.datasets.mrclam:load_mrclam", mrclam_files()),
        ("plaza1", "slamkit.datasets.plaza:load_plaza1", PLAZA1_FILES),
    ],
)
def test_registry_entries_load(data_root: Path, name: str, target: str, files: tuple) -> None:
    """The entries proposed for datasets/registry.py load through the registry's machinery
    and describe themselves as JSON."""
    import json

    from slamkit.datasets import DatasetEntry, dataset_available

    entry = DatasetEntry(name, "real", "test entry", target, files)
    _need(data_root, files)
    assert dataset_available(entry, data_root)
    ds = entry.loader()({"max_duration_s": 30.0}, seed=0, data_root=data_root)
    assert ds.name == name
    summary = json.loads(json.dumps(ds.summary()))
    assert summary["kind"] == "real" and summary["events"]["LandmarkReadings"] > 0


# ------------------------------------------------------------------ Plaza: malformed rows
# The first rows of the four files, laid out as in the real files (DR and TD: tab-separated
# with leading blanks and a trailing tab; GT and TL: one comment line, then space-separated).
_PLAZA_HEAD = {
    "Plaza1_DR.txt": [
        "  3.8570532019138336e+003\t  2.3483858154428326e-004\t -5.2000000000163027e-005\t",
        "  3.8572534408569336e+003\t  2.7240746312308210e-004\t  2.6000000000081510e-005\t",
        "  3.8574533009529114e+003\t  2.3057904745266982e-004\t -7.4000000000573607e-005\t",
        "  3.8576528358459473e+003\t  2.4512843424856311e-004\t -4.8999999999743693e-005\t",
        "  3.8578526110649109e+003\t  2.1071781958270869e-004\t -3.6999999999842714e-005\t",
    ],
    "Plaza1_TD.txt": [
        "  3.8580620000362396e+003\t  2.0000000000000000e+000\t  5.0000000000000000e+000\t"
        "  6.5466007843625079e+001\t",
        "  3.8583120000362396e+003\t  2.0000000000000000e+000\t  5.0000000000000000e+000\t"
        "  6.6120147867149058e+001\t",
        "  3.8585460000038147e+003\t  2.0000000000000000e+000\t  6.0000000000000000e+000\t"
        "  3.5872649691111221e+001\t",
        "  3.8587809998989105e+003\t  2.0000000000000000e+000\t  6.0000000000000000e+000\t"
        "  3.4338759262723272e+001\t",
    ],
    "Plaza1_GT.csv": [
        "# time_s x_m y_m heading_rad  (ground truth from laser scan matching; derived from "
        "Plaza1_.mat)",
        "3856.857346 0 0 4.222432",
        "3857.053202 2.99999956e-05 2.699997276e-05 4.22238",
        "3857.253441 5.699996836e-05 0.000115999952 4.222406",
        "3857.453301 5.799997598e-05 0.0001039998606 4.222332",
    ],
    "Plaza1_TL.csv": [
        "# beacon_id x_m y_m  (surveyed beacon locations; derived from Plaza1_.mat)",
        "0 -46.623234 11.025549",
        "1 11.036124 -6.958689",
        "6 22.053129 23.848482",
        "5 -17.664893 59.009181",
    ],
}


def _write_plaza(root: Path, changes: dict[tuple[str, int], str] | None = None) -> Path:
    """The small Plaza 1 folder under ``root`` with line ``n`` (1-based) of ``file`` replaced
    by ``changes[(file, n)]``; returns the folder."""
    folder = root / "landmarks" / "plaza"
    folder.mkdir(parents=True, exist_ok=True)
    for name, lines in _PLAZA_HEAD.items():
        out = list(lines)
        for (file, n), text in (changes or {}).items():
            if file == name:
                out[n - 1] = text
        (folder / name).write_text("\n".join(out) + "\n")
    return folder


def test_plaza_small_copy_loads(tmp_path: Path) -> None:
    """The hand-made head of the files is a valid Plaza 1 (the cases below break one row)."""
    _write_plaza(tmp_path)
    ds = load_plaza1({}, seed=0, data_root=tmp_path)
    assert ds.metadata["odometry_rows"] == 5 and ds.metadata["readings_kept"] == 4
    assert ds.truth.times is not None and ds.truth.times.size == 4
    assert ds.known_landmarks is not None and sorted(ds.known_landmarks.ids) == [0, 1, 5, 6]


_DR, _TD, _GT, _TL = "Plaza1_DR.txt", "Plaza1_TD.txt", "Plaza1_GT.csv", "Plaza1_TL.csv"


@pytest.mark.parametrize(
    "file,line,text,match",
    [
        (_DR, 3, "  3.8574533009529114e+003\t  2.3057904745266982e-004\t", "column"),
        (_DR, 2, "  3.8572534408569336e+003\t  0.27x\t  2.6e-005\t", "number"),
        (_DR, 4, "  3.8572534408569336e+003\t  2.4e-004\t -4.8e-005\t", "increasing times"),
        (_DR, 1, "  3.8560000000000000e+003\t  2.3e-004\t -5.2e-005\t", "not after"),
        (_TD, 2, "  3.8583120000362396e+003\t  2.0\t  5.0\t -6.6120147867149058e+001\t", "pos"),
        (_TD, 3, "  3.8585460000038147e+003\t  2.0\t  5.5\t  3.5872649691111221e+001\t", "integer"),
        (_TD, 4, "  3.8587809998989105e+003\t  2.0\t  6.0\t  nan\t", "finite"),
        (_GT, 4, "3857.253441 5.699996836e-05 0.000115999952", "column"),
        (_GT, 5, "3857.0 5.799997598e-05 0.0001039998606 4.222332", "non-decreasing"),
        (_TL, 3, "1.5 11.036124 -6.958689", "integer beacon id"),
    ],
)
def test_plaza_malformed_row_names_file_and_line(
    tmp_path: Path, file: str, line: int, text: str, match: str
) -> None:
    folder = _write_plaza(tmp_path, {(file, line): text})
    with pytest.raises(DatasetFormatError, match=match) as err:
        load_plaza1({}, seed=0, data_root=tmp_path)
    assert err.value.path == folder / file
    assert err.value.line == line
    assert f"{file}:{line}" in str(err.value)


def test_plaza_malformed_files_without_a_line(tmp_path: Path) -> None:
    """Errors about a whole file name the file (there is no single line to blame); a
    duplicated beacon id names the line of its second listing."""
    folder = _write_plaza(tmp_path, {(_TL, 5): "1 -17.664893 59.009181"})  # id 1 twice
    with pytest.raises(DatasetFormatError, match="beacon id 1 is listed twice") as err:
        load_plaza1({}, seed=0, data_root=tmp_path)
    assert err.value.path == folder / _TL and err.value.line == 5
    assert f"{_TL}:5: beacon id 1 is listed twice (first on line " in str(err.value)
    (folder / _GT).write_text(_PLAZA_HEAD[_GT][0] + "\n" + _PLAZA_HEAD[_GT][1] + "\n")
    (folder / _TL).write_text("\n".join(_PLAZA_HEAD[_TL]) + "\n")
    with pytest.raises(DatasetFormatError, match="at least 2 rows") as err:
        load_plaza1({}, seed=0, data_root=tmp_path)
    assert err.value.path == folder / _GT
