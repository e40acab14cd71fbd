"""Every result on disk: landmark CSV, KITTI trajectories, the true path beside the estimate."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.app import RunRequest, run_job
from slamkit.datasets import load_dataset
from slamkit.errors import ConfigError, DatasetFormatError
from slamkit.io import (
    read_kitti,
    read_kitti_matrices,
    read_landmarks_csv,
    read_tum,
    read_tum_matrices,
    write_kitti,
    write_landmarks_csv,
    write_tum,
)
from slamkit.maps import LandmarkMap


def test_landmark_csv_round_trips_positions_ids_and_covariances(tmp_path, rng):
    pos = rng.normal(size=(7, 2)) * 50
    a = rng.normal(size=(7, 2, 2))
    cov = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(2)
    lm = LandmarkMap(pos, np.array([3, 1, 99, 4, 5, 1000002, 7]))
    write_landmarks_csv(tmp_path / "l.csv", lm, cov)
    back, back_cov = read_landmarks_csv(tmp_path / "l.csv")
    np.testing.assert_array_equal(back.ids, lm.ids)
    np.testing.assert_allclose(back.positions, pos, rtol=1e-8)
    np.testing.assert_allclose(back_cov, cov, rtol=1e-8)
    write_landmarks_csv(tmp_path / "m.csv", lm)
    assert read_landmarks_csv(tmp_path / "m.csv")[1] is None


def test_landmark_csv_errors_name_the_line(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("id,x,y,cov_xx,cov_xy,cov_yy\n1,2,3,,,\n2,x,3,,,\n")
    with pytest.raises(DatasetFormatError, match=r"bad\.csv:3"):
        read_landmarks_csv(p)
    p.write_text("id,x,y,cov_xx,cov_xy,cov_yy\n1,2,3,,,\n4,2,3,,,\n1,4,5,,,\n")
    with pytest.raises(DatasetFormatError) as info:
        read_landmarks_csv(p)
    assert str(info.value) == f"{p}:4: landmark id 1 is listed twice (first on line 2)"
    assert info.value.line == 4


def test_kitti_round_trips_planar_poses_and_agrees_with_tum(tmp_path, rng):
    poses = np.column_stack([rng.normal(size=(20, 2)) * 10, rng.uniform(-np.pi, np.pi, 20)])
    times = np.arange(20) * 0.1
    write_kitti(tmp_path / "t.kitti", poses, times=times, times_path=tmp_path / "times.txt")
    np.testing.assert_allclose(read_kitti(tmp_path / "t.kitti"), poses, atol=1e-7)
    np.testing.assert_allclose(np.loadtxt(tmp_path / "times.txt"), times)
    write_tum(tmp_path / "t.tum", times, poses)
    _, m_tum = read_tum_matrices(tmp_path / "t.tum")
    np.testing.assert_allclose(read_kitti_matrices(tmp_path / "t.kitti"), m_tum, atol=1e-7)
    # A rotation about z by θ: the matrix's first column is (cos θ, sin θ, 0).
    first_column = np.column_stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])])
    np.testing.assert_allclose(m_tum[:, :2, 0], first_column, atol=1e-7)


def test_a_landmark_slam_run_writes_its_map_the_truth_and_kitti(tmp_path):
    out = tmp_path / "o"
    report = run_job(
        RunRequest("ekf-slam", "five-features", out, seed=2, plots=False, formats=("kitti",))
    )
    for name in ("landmarks.csv", "groundtruth.tum", "groundtruth_landmarks.csv",
                 "trajectory.kitti", "times.txt"):  # fmt: skip
        assert name in report.files
    lm, cov = read_landmarks_csv(out / "landmarks.csv")
    est = report.result.output.landmarks
    assert est is not None and cov is not None
    np.testing.assert_array_equal(lm.ids, est.landmarks.ids)
    np.testing.assert_allclose(lm.positions, est.landmarks.positions, rtol=1e-8)
    # The mapped landmarks lie near the true ones (ids are the data set's for EKF-SLAM).
    truth = load_dataset("five-features", seed=2).truth
    err = np.linalg.norm(lm.positions - truth.landmarks.position_of(lm.ids), axis=1)
    assert np.all(err < 5 * np.sqrt(cov[:, 0, 0] + cov[:, 1, 1]) + 0.05)
    t, poses = read_tum(out / "groundtruth.tum")
    np.testing.assert_allclose(t, truth.times)
    np.testing.assert_allclose(poses[:, :2], truth.poses[:, :2], atol=1e-7)
    np.testing.assert_allclose(read_kitti(out / "trajectory.kitti"), report.result.poses,
                               atol=1e-7)  # fmt: skip


def test_a_run_without_a_map_writes_no_landmarks_and_unknown_formats_fail_early(tmp_path):
    report = run_job(RunRequest("dead-reckoning", "five-features", tmp_path / "o", plots=False))
    assert "landmarks.csv" not in report.files and "groundtruth.tum" in report.files
    with pytest.raises(ConfigError, match="xyz"):
        run_job(RunRequest("dead-reckoning", "five-features", tmp_path / "p", formats=("xyz",)))
    assert not (tmp_path / "p").exists()
