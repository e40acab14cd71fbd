"""Least-squares point-set alignment (Umeyama) and the Similarity value."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from slamkit.errors import GeometryError, InputError, NonFiniteError, ShapeError
from slamkit.geometry.alignment import Similarity, align_points, align_points_2d
from slamkit.geometry.pose2 import transform_points


def rot2(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def cost(sim: Similarity, src: np.ndarray, dst: np.ndarray) -> float:
    return float(np.sum((sim.apply_to_points(src) - dst) ** 2))


# --------------------------------------------------------------------- exact recovery
def test_recovers_rigid_2d_exactly() -> None:
    rng = np.random.default_rng(0)
    src = rng.normal(size=(20, 2)) * 3.0
    R, t = rot2(0.7), np.array([1.5, -2.0])
    dst = src @ R.T + t
    sim = align_points(src, dst)
    np.testing.assert_allclose(sim.rotation, R, atol=1e-10)
    np.testing.assert_allclose(sim.translation, t, atol=1e-10)
    assert sim.scale == 1.0
    assert sim.angle == pytest.approx(0.7, abs=1e-10)
    np.testing.assert_allclose(sim.as_pose(), [1.5, -2.0, 0.7], atol=1e-10)


def test_recovers_similarity_2d_exactly() -> None:
    rng = np.random.default_rng(1)
    src = rng.uniform(-5, 5, size=(15, 2))
    R, t, s = rot2(-2.5), np.array([10.0, 4.0]), 0.37
    dst = s * src @ R.T + t
    sim = align_points(src, dst, with_scale=True)
    assert sim.angle == pytest.approx(-2.5, abs=1e-10)
    np.testing.assert_allclose(sim.translation, t, atol=1e-10)
    assert sim.scale == pytest.approx(s, abs=1e-10)


def test_two_points_are_enough_in_2d() -> None:
    src = np.array([[0.0, 0.0], [1.0, 0.0]])
    dst = np.array([[2.0, 3.0], [2.0, 5.0]])  # rotated by +90°, scaled by 2, shifted
    sim = align_points(src, dst, with_scale=True)
    assert sim.angle == pytest.approx(np.pi / 2, abs=1e-12)
    assert sim.scale == pytest.approx(2.0, abs=1e-12)
    np.testing.assert_allclose(sim.translation, [2.0, 3.0], atol=1e-12)


def test_recovers_similarity_3d_exactly() -> None:
    rng = np.random.default_rng(2)
    src = rng.normal(size=(30, 3))
    R = Rotation.from_rotvec([0.3, -1.1, 0.8]).as_matrix()
    t, s = np.array([0.5, -4.0, 2.0]), 2.5
    dst = s * src @ R.T + t
    sim = align_points(src, dst, with_scale=True)
    np.testing.assert_allclose(sim.rotation, R, atol=1e-10)
    np.testing.assert_allclose(sim.translation, t, atol=1e-10)
    assert sim.scale == pytest.approx(s, abs=1e-10)
    rigid = align_points(src, dst, with_scale=False)
    np.testing.assert_allclose(rigid.rotation, R, atol=1e-10)  # the rotation is scale-free


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    dim=st.sampled_from([2, 3]),
    n=st.integers(4, 40),
    with_scale=st.booleans(),
)
def test_property_recovers_random_transform(seed: int, dim: int, n: int, with_scale: bool) -> None:
    rng = np.random.default_rng(seed)
    src = rng.normal(size=(n, dim)) * rng.uniform(0.1, 10)
    if dim == 3:
        R = Rotation.random(random_state=seed).as_matrix()
    else:
        R = rot2(rng.uniform(-np.pi, np.pi))
    t = rng.normal(size=dim) * 5
    s = rng.uniform(0.2, 5.0) if with_scale else 1.0
    dst = s * src @ R.T + t
    sim = align_points(src, dst, with_scale=with_scale)
    np.testing.assert_allclose(sim.rotation, R, atol=1e-8)
    np.testing.assert_allclose(sim.translation, t, atol=1e-8 * (1 + np.abs(t).max()))
    assert sim.scale == pytest.approx(s, rel=1e-9)
    assert np.linalg.det(sim.rotation) == pytest.approx(1.0, abs=1e-12)


# ---------------------------------------------------------------------------- weights
def test_zero_weighted_outliers_are_ignored() -> None:
    rng = np.random.default_rng(3)
    src = rng.normal(size=(12, 2))
    R, t = rot2(1.2), np.array([-3.0, 0.25])
    dst = src @ R.T + t
    dst[[2, 7]] += [[50.0, -20.0], [-8.0, 30.0]]  # gross outliers
    w = np.ones(12)
    w[[2, 7]] = 0.0
    sim = align_points(src, dst, weights=w)
    assert sim.angle == pytest.approx(1.2, abs=1e-10)
    np.testing.assert_allclose(sim.translation, t, atol=1e-10)
    # ...and unweighted they do spoil the fit, so the test above is not vacuous.
    assert abs(align_points(src, dst).angle - 1.2) > 1e-2


def test_weights_need_not_be_normalised() -> None:
    rng = np.random.default_rng(4)
    src, dst = rng.normal(size=(10, 2)), rng.normal(size=(10, 2))
    w = rng.uniform(0.1, 2.0, size=10)
    a = align_points(src, dst, weights=w, with_scale=True)
    b = align_points(src, dst, weights=7.5 * w, with_scale=True)
    np.testing.assert_allclose(a.as_matrix(), b.as_matrix(), atol=1e-12)


def test_integer_weights_equal_repeated_points() -> None:
    rng = np.random.default_rng(5)
    src, dst = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
    w = np.array([1, 3, 1, 2, 1, 1])
    a = align_points(src, dst, weights=w, with_scale=True)
    b = align_points(np.repeat(src, w, axis=0), np.repeat(dst, w, axis=0), with_scale=True)
    np.testing.assert_allclose(a.as_matrix(), b.as_matrix(), atol=1e-12)


# ------------------------------------------------------------------------- reflection
def test_reflected_target_gives_the_best_proper_rotation_2d() -> None:
    rng = np.random.default_rng(6)
    src = rng.normal(size=(25, 2)) * [3.0, 1.0]
    dst = src * [1.0, -1.0]  # mirror image: no rotation maps one onto the other
    sim = align_points(src, dst)
    assert np.linalg.det(sim.rotation) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(sim.rotation.T @ sim.rotation, np.eye(2), atol=1e-12)
    # It is the least-squares optimum among all proper rotations (dense scan of the angle,
    # with the optimal translation for each).
    mu_s, mu_t = src.mean(0), dst.mean(0)
    best = min(
        np.sum(((src - mu_s) @ rot2(a).T - (dst - mu_t)) ** 2)
        for a in np.linspace(-np.pi, np.pi, 20001)
    )
    assert cost(sim, src, dst) <= best + 1e-9


def test_reflected_target_gives_proper_rotation_3d() -> None:
    # The 8 corners of a 4 x 2 x 1 box, mirrored in z: cross-covariance Σ = diag(16, 4, -1).
    corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T
    src = corners * [4.0, 2.0, 1.0]
    dst = src * [1.0, 1.0, -1.0]
    sim = align_points(src, dst, with_scale=True)
    assert np.linalg.det(sim.rotation) == pytest.approx(1.0, abs=1e-12)
    # The flattest axis is the one sacrificed: the best rotation is the identity and the
    # least-squares scale is tr(D S) / σ² = (16 + 4 − 1) / (16 + 4 + 1).
    np.testing.assert_allclose(sim.rotation, np.eye(3), atol=1e-12)
    assert sim.scale == pytest.approx(19 / 21, abs=1e-12)
    np.testing.assert_allclose(sim.translation, 0.0, atol=1e-12)


# ------------------------------------------------------------------- noise statistics
def test_noise_errors_match_theory() -> None:
    """Target noise σ per axis: angle std ≈ σ / (sqrt(N) r_rms), centroid std ≈ σ/sqrt(N)."""
    rng = np.random.default_rng(8)
    n, sigma = 200, 0.01
    src = rng.uniform(-10, 10, size=(n, 2))
    R, t = rot2(0.4), np.array([3.0, -1.0])
    dst = src @ R.T + t + rng.normal(scale=sigma, size=(n, 2))
    sim = align_points(src, dst)
    centred = src - src.mean(0)
    r_rms = np.sqrt(np.mean(np.sum(centred**2, axis=1)))
    sd_angle = sigma / (np.sqrt(n) * r_rms)
    assert abs(sim.angle - 0.4) < 5 * sd_angle
    # Translation error = centroid noise + lever arm of the angle error about the origin.
    sd_t = np.sqrt(sigma**2 / n + np.sum(src.mean(0) ** 2) * sd_angle**2)
    assert np.linalg.norm(sim.translation - t) < 5 * np.sqrt(2) * sd_t


def test_least_squares_scale_beats_ratio_of_spreads_under_noise() -> None:
    rng = np.random.default_rng(9)
    src = rng.normal(size=(50, 2))
    dst = 1.7 * src @ rot2(0.3).T + rng.normal(scale=0.3, size=(50, 2))
    sim = align_points(src, dst, with_scale=True)
    a, b = src - src.mean(0), dst - dst.mean(0)
    ratio = np.sqrt(np.sum(b**2) / np.sum(a**2))
    other = Similarity(sim.rotation, dst.mean(0) - ratio * sim.rotation @ src.mean(0), ratio)
    assert ratio > sim.scale  # the spread ratio also counts the noise as "size"
    assert cost(sim, src, dst) < cost(other, src, dst)


# ------------------------------------------------------------------------- Similarity
def test_apply_to_poses_hand_value() -> None:
    sim = Similarity(rot2(np.pi / 2), np.array([1.0, 2.0]), 2.0)
    out = sim.apply_to_poses([[1.0, 0.0, 3 * np.pi / 4], [0.0, 0.0, 0.0]])
    # (1, 0) -> rotate (0, 1) -> scale (0, 2) -> shift (1, 4); heading 3π/4 + π/2 = 5π/4 ≡ −3π/4.
    np.testing.assert_allclose(out, [[1.0, 4.0, -3 * np.pi / 4], [1.0, 2.0, np.pi / 2]])


def test_from_pose_matches_pose2_and_round_trips() -> None:
    pose = np.array([0.3, -1.2, 2.9])
    sim = Similarity.from_pose(pose)
    pts = np.array([[1.0, 2.0], [-0.5, 0.1], [0.0, 0.0]])
    np.testing.assert_allclose(sim.apply_to_points(pts), transform_points(pose, pts))
    np.testing.assert_allclose(sim.as_pose(), pose, atol=1e-15)


def test_inverse_and_composition() -> None:
    a = Similarity(Rotation.from_rotvec([0.1, 0.2, -0.3]).as_matrix(), np.array([1, 2, 3]), 1.5)
    b = Similarity(Rotation.from_rotvec([-0.4, 0.0, 0.9]).as_matrix(), np.array([0, -1, 5]), 0.2)
    p = np.array([[0.3, 0.4, -2.0], [1.0, 1.0, 1.0]])
    np.testing.assert_allclose((a @ b).apply_to_points(p), a.apply_to_points(b.apply_to_points(p)))
    np.testing.assert_allclose((a @ a.inverse()).as_matrix(), np.eye(4), atol=1e-14)
    np.testing.assert_allclose(a.as_matrix() @ a.inverse().as_matrix(), np.eye(4), atol=1e-14)


def test_similarity_is_immutable_and_copies() -> None:
    R = np.eye(2)
    sim = Similarity(R, np.zeros(2))
    assert R.flags.writeable  # the caller's array is untouched
    with pytest.raises(ValueError):
        sim.rotation[0, 0] = 2.0


def test_similarity_validation() -> None:
    with pytest.raises(InputError, match="determinant"):
        Similarity(np.diag([1.0, -1.0]), np.zeros(2))
    with pytest.raises(InputError, match="orthonormal"):
        Similarity(np.array([[1.0, 0.1], [0.0, 1.0]]), np.zeros(2))
    with pytest.raises(InputError, match="scale"):
        Similarity(np.eye(2), np.zeros(2), 0.0)
    with pytest.raises(ShapeError):
        Similarity(np.eye(2), np.zeros(3))
    three = Similarity.identity(3)
    with pytest.raises(ShapeError, match="2-D"):
        _ = three.angle
    with pytest.raises(ShapeError, match="2-D"):
        three.apply_to_poses(np.zeros((1, 3)))
    with pytest.raises(InputError, match="scale"):
        Similarity(np.eye(2), np.zeros(2), 2.0).as_pose()


# ------------------------------------------------------------------------- bad inputs
@pytest.mark.parametrize(
    ("src", "dst", "weights", "match"),
    [
        (np.zeros((0, 2)), np.zeros((0, 2)), None, "at least one"),
        ([[1.0, 2.0]], [[3.0, 4.0]], None, "coincide"),
        ([[1.0, 2.0], [1.0, 2.0]], [[0.0, 0.0], [1.0, 0.0]], None, "source points"),
        ([[0.0, 0.0], [1.0, 0.0]], [[5.0, 5.0], [5.0, 5.0]], None, "target points"),
        ([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [1.0, 0.0]], [0.0, 0.0], "weights are zero"),
        ([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [1.0, 0.0]], [1.0, 0.0], "coincide"),
        (
            [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [5.0, 5.0, 5.0]],
            [[0.0, 1.0, 0.0], [1.0, 2.0, 0.0], [2.0, 3.0, 0.0], [3.0, 4.0, 0.0]],
            None,
            "not determined",
        ),
    ],
)
def test_degenerate_configurations_raise(
    src: object, dst: object, weights: object, match: str
) -> None:
    with pytest.raises(GeometryError, match=match):
        align_points(src, dst, weights=weights)  # type: ignore[arg-type]


def test_bad_inputs_raise_typed_errors() -> None:
    pts = np.arange(8.0).reshape(4, 2)
    with pytest.raises(ShapeError):
        align_points(pts, pts[:3])
    with pytest.raises(ShapeError, match="D >= 2"):
        align_points(pts.reshape(8, 1), pts.reshape(8, 1))
    with pytest.raises(NonFiniteError):
        align_points(np.where(pts == 3, np.nan, pts), pts)
    with pytest.raises(InputError, match="non-negative"):
        align_points(pts, pts, weights=[1.0, -1.0, 1.0, 1.0])
    with pytest.raises(ShapeError):
        align_points(pts, pts, weights=[1.0, 1.0])
    with pytest.raises(ShapeError):
        align_points_2d(np.zeros((4, 3)), np.zeros((4, 3)))
    assert align_points_2d(pts, pts + 1).as_pose() == pytest.approx([1.0, 1.0, 0.0])
