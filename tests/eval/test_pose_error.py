"""APE/RPE between trajectory files by evo's rules: hand-checked values, and evo's own numbers
on the same files (evo is an optional peer: ``pip install slamkit[evo]``)."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets import load_dataset
from slamkit.errors import InputError, ShapeError
from slamkit.eval.pose_error import (
    associate_stamps,
    compare_trajectories,
    relative_pose_error_se3,
    rotation_angles,
)
from slamkit.geometry import SO3
from slamkit.io import read_kitti_matrices, read_tum_matrices, write_kitti, write_tum


def _se3(rotations: np.ndarray, positions: np.ndarray) -> np.ndarray:
    m = np.zeros((positions.shape[0], 4, 4))
    m[:, :3, :3] = rotations
    m[:, :3, 3] = positions
    m[:, 3, 3] = 1.0
    return m


def _planar(poses: np.ndarray) -> np.ndarray:
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    r = np.zeros((poses.shape[0], 3, 3))
    r[:, 0, 0], r[:, 0, 1], r[:, 1, 0], r[:, 1, 1], r[:, 2, 2] = c, -s, s, c, 1.0
    return _se3(r, np.column_stack([poses[:, :2], np.zeros(poses.shape[0])]))


def _write_tum3d(path, times, poses):
    q = SO3.from_matrix(poses[:, :3, :3]).wxyz
    rows = np.column_stack([times, poses[:, :3, 3], q[:, 1:], q[:, :1]])
    np.savetxt(path, rows, fmt="%.9f")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A simulated truth (landmark-loop) and a noisy, rotated, scaled, time-jittered estimate
    at a different rate, planar (TUM, KITTI) and lifted to 3D with tilts (TUM)."""
    rng = np.random.default_rng(7)
    truth = load_dataset("landmark-loop", seed=3).truth
    t, p = truth.times[::2], truth.poses[::2]
    d = tmp_path_factory.mktemp("traj")
    # The estimate: every third truth pose, drifting and noisy, 1.3x scale, rotated, and its
    # clock 0.5 s ahead with 6 ms jitter, so some stamps have no partner within 10 ms.
    k = np.arange(0, t.size, 3)
    drift = np.cumsum(rng.normal(0, 0.02, (k.size, 3)), axis=0)
    est = p[k] + drift + rng.normal(0, [0.05, 0.05, 0.01], (k.size, 3))
    c, s = np.cos(0.4), np.sin(0.4)
    xy = 1.3 * est[:, :2] @ np.array([[c, -s], [s, c]]).T + [4.0, -2.0]
    est = np.column_stack([xy, est[:, 2] + 0.4])
    t_est = t[k] + 0.5 + rng.normal(0, 0.006, k.size)
    write_tum(d / "ref.tum", t, p)
    write_tum(d / "est.tum", t_est, est)
    write_kitti(d / "ref.kitti", p[k])
    write_kitti(d / "est.kitti", est)
    # 3D: tilt every pose a little and give it height.
    tilt = SO3.exp(rng.normal(0, 0.05, (t.size, 3))).as_matrix()
    ref3 = _planar(p)
    ref3[:, :3, :3] = ref3[:, :3, :3] @ tilt
    ref3[:, 2, 3] = np.sin(t / 10.0)
    est3 = ref3[k].copy()
    est3[:, :3, :3] = est3[:, :3, :3] @ SO3.exp(rng.normal(0, 0.02, (k.size, 3))).as_matrix()
    est3[:, :3, 3] += np.cumsum(rng.normal(0, 0.03, (k.size, 3)), axis=0)
    _write_tum3d(d / "ref3.tum", t, ref3)
    _write_tum3d(d / "est3.tum", t_est, est3)
    return d


def test_association_pairs_the_nearest_stamp_within_the_limit():
    ref = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    est = np.array([0.96, 2.04, 2.5, 10.0])  # 2.5: a tie between 2 and 3, too far anyway
    i_ref, i_est = associate_stamps(ref, est, max_diff=0.05)
    assert i_ref.tolist() == [1, 2] and i_est.tolist() == [0, 1]
    i_ref, i_est = associate_stamps(ref, est, max_diff=0.5)  # the tie goes to the earlier
    assert i_ref.tolist() == [1, 2, 2] and i_est.tolist() == [0, 1, 2]
    i_ref, i_est = associate_stamps(ref, est - 1.0, max_diff=0.05, offset=1.0)
    assert i_ref.tolist() == [1, 2]
    with pytest.raises(InputError, match="no matching time stamps"):
        associate_stamps(ref, est + 100.0)


def test_a_known_rigid_motion_aligns_to_zero_error_and_rpe_ignores_it():
    rng = np.random.default_rng(1)
    ref = _se3(SO3.exp(rng.normal(size=(30, 3))).as_matrix(), rng.normal(size=(30, 3)) * 5)
    g = _se3(SO3.exp(np.array([[0.3, -0.2, 1.0]])).as_matrix(), np.array([[1.0, 2.0, 3.0]]))[0]
    est = np.einsum("ij,njk->nik", np.linalg.inv(g), ref)
    res = compare_trajectories(ref, est, alignment="se3")
    assert res.ape.max < 1e-9 and res.ape_rotation_deg.max < 1e-6
    raw = compare_trajectories(ref, est, alignment="none")
    assert raw.ape.min > 0.1 and raw.rpe.max < 1e-9  # relative motion is frame-free
    # Sim(3) recovers a scale: estimate = ref shrunk by 2 about the origin.
    small = ref.copy()
    small[:, :3, 3] /= 2.0
    sim = compare_trajectories(ref, small, alignment="sim3")
    assert sim.similarity is not None and sim.similarity.scale == pytest.approx(2.0, rel=1e-12)
    assert sim.ape.max < 1e-9


def test_no_alignment_by_default_and_scale_alone_by_hand():
    rng = np.random.default_rng(2)
    ref = _se3(SO3.exp(rng.normal(size=(20, 3))).as_matrix(), rng.normal(size=(20, 3)) * 4)
    g = _se3(SO3.exp(np.array([[0.0, 0.0, 0.7]])).as_matrix(), np.array([[1.0, -2.0, 0.5]]))[0]
    est = np.einsum("ij,njk->nik", g, ref)
    est[:, :3, 3] *= 0.5  # the estimate: the reference moved by g, then half its size
    default = compare_trajectories(ref, est)
    assert default.alignment == "none" and default.similarity is None
    raw = np.linalg.norm(est[:, :3, 3] - ref[:, :3, 3], axis=1)  # by hand: no alignment
    np.testing.assert_allclose(default.ape_translation, raw, rtol=1e-12)
    # sim3 undoes g and the half exactly; scale (evo's -s) only doubles the translations.
    assert compare_trajectories(ref, est, alignment="sim3").ape.max < 1e-9
    scaled = compare_trajectories(ref, est, alignment="scale")
    assert scaled.similarity is not None
    assert scaled.similarity.scale == pytest.approx(2.0, rel=1e-12)
    np.testing.assert_allclose(scaled.similarity.rotation, np.eye(3))
    by_hand = np.linalg.norm(2.0 * est[:, :3, 3] - ref[:, :3, 3], axis=1)
    np.testing.assert_allclose(scaled.ape_translation, by_hand, rtol=1e-9)
    assert scaled.ape.rmse > 1.0  # the motion g is left in


def test_rpe_by_hand_and_rotation_angles_near_zero():
    ref = _planar(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]))
    est = _planar(np.array([[0.0, 0, 0], [1.1, 0, 0.1], [2.0, 0.3, 0.1]]))
    pairs, trans, rot = relative_pose_error_se3(ref, est)
    assert pairs.tolist() == [[0, 1], [1, 2]]
    # pair 0: relative est (1.1, 0, 0.1) against (1, 0, 0): E = (0.1, 0, 0.1)
    assert trans[0] == pytest.approx(0.1, abs=1e-12) and rot[0] == pytest.approx(0.1, abs=1e-12)
    angles = rotation_angles(SO3.exp(np.array([[1e-9, 0, 0], [0, 2.0, 0]])).as_matrix())
    np.testing.assert_allclose(angles, [1e-9, 2.0], rtol=1e-9)
    with pytest.raises(ShapeError, match="same number of poses"):
        compare_trajectories(ref, est[:2])


def _evo_numbers(ref_path, est_path, kind, alignment, *, max_diff, offset, delta, all_pairs,
                 unit="frames"):  # fmt: skip
    from evo.core import metrics, sync
    from evo.tools import file_interface

    if kind == "tum":
        ref = file_interface.read_tum_trajectory_file(str(ref_path))
        est = file_interface.read_tum_trajectory_file(str(est_path))
        ref, est = sync.associate_trajectories(ref, est, max_diff=max_diff, offset_2=offset)
    else:
        ref = file_interface.read_kitti_poses_file(str(ref_path))
        est = file_interface.read_kitti_poses_file(str(est_path))
    if alignment != "none":  # evo_ape's -a, -as, -s
        est.align(ref, correct_scale=alignment == "sim3", correct_only_scale=alignment == "scale")
    out = {}
    evo_unit = metrics.Unit.frames if unit == "frames" else metrics.Unit.meters
    for name, metric in (
        ("ape", metrics.APE(metrics.PoseRelation.translation_part)),
        ("ape_rot", metrics.APE(metrics.PoseRelation.rotation_angle_deg)),
        ("rpe", metrics.RPE(metrics.PoseRelation.translation_part, delta, evo_unit,
                            all_pairs=all_pairs)),
        ("rpe_rot", metrics.RPE(metrics.PoseRelation.rotation_angle_deg, delta,
                                evo_unit, all_pairs=all_pairs)),
    ):  # fmt: skip
        metric.process_data((ref, est))
        out[name] = metric.get_all_statistics()
    return out


@pytest.mark.parametrize(
    ("kind", "ref", "est", "alignment", "delta", "all_pairs", "unit"),
    [
        ("tum", "ref.tum", "est.tum", "se3", 1, False, "frames"),
        ("tum", "ref.tum", "est.tum", "sim3", 5, True, "frames"),
        ("tum", "ref.tum", "est.tum", "none", 3, False, "frames"),
        ("tum", "ref3.tum", "est3.tum", "se3", 1, False, "frames"),
        ("tum", "ref3.tum", "est3.tum", "sim3", 4, False, "frames"),
        ("kitti", "ref.kitti", "est.kitti", "sim3", 2, True, "frames"),
        ("tum", "ref.tum", "est.tum", "se3", 5.0, False, "m"),
        ("tum", "ref3.tum", "est3.tum", "sim3", 8.0, True, "m"),
        ("tum", "ref3.tum", "est3.tum", "scale", 2, False, "frames"),
        ("kitti", "ref.kitti", "est.kitti", "scale", 1, False, "frames"),
    ],
)
def test_numbers_equal_evos_on_the_same_files(
    files, kind, ref, est, alignment, delta, all_pairs, unit
):
    pytest.importorskip("evo", reason="evo is an optional peer: pip install 'slamkit[evo]'")
    max_diff, offset = 0.01, -0.5
    if kind == "tum":
        t_ref, q = read_tum_matrices(files / ref)
        t_est, p = read_tum_matrices(files / est)
        ours = compare_trajectories(q, p, times_ref=t_ref, times_est=t_est, alignment=alignment,
                                    max_diff=max_diff, offset=offset, delta=delta,
                                    all_pairs=all_pairs, delta_unit=unit)  # fmt: skip
        assert 0 < ours.matched < ours.estimate_poses  # some stamps have no partner
    else:
        q, p = read_kitti_matrices(files / ref), read_kitti_matrices(files / est)
        ours = compare_trajectories(q, p, alignment=alignment, delta=delta, all_pairs=all_pairs)
    theirs = _evo_numbers(files / ref, files / est, kind, alignment, max_diff=max_diff,
                          offset=offset, delta=delta, all_pairs=all_pairs, unit=unit)  # fmt: skip
    for name, stats in (("ape", ours.ape), ("ape_rot", ours.ape_rotation_deg),
                        ("rpe", ours.rpe), ("rpe_rot", ours.rpe_rotation_deg)):  # fmt: skip
        for key in ("rmse", "mean", "median", "std", "min", "max", "sse"):
            assert getattr(stats, key) == pytest.approx(theirs[name][key], rel=1e-6, abs=1e-6), (
                name,
                key,
            )
    if alignment == "none":
        assert ours.ape.rmse > 1.0  # the estimate's frame is rotated, scaled, shifted


def test_unsorted_stamps_are_matched_by_a_full_search():
    ref = np.array([3.0, 1.0, 2.0, 0.0])  # the shorter one is walked in its order
    est = np.array([2.996, 0.0, 5.0, 1.004, 2.0])  # the longer one is searched: unsorted
    i_ref, i_est = associate_stamps(ref, est, max_diff=0.01)
    assert i_ref.tolist() == [0, 1, 2, 3] and i_est.tolist() == [0, 3, 4, 1]
