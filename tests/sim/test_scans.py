"""Simulated scan pairs: the motion is ``between`` the poses, noise-free points lie on the
walls, the random pairs have the stated motion, and a seed fixes every number."""

from __future__ import annotations

import numpy as np

from slamkit.geometry.pose2 import between, transform_points
from slamkit.sim import corridor_world, random_scan_pairs, rooms_world, simulated_scan_pair

BEAMS = np.linspace(-np.pi / 2, np.pi / 2, 90)


def _distance_to_walls(points, segments):
    a, b = segments[:, 0], segments[:, 1]
    d = b - a
    t = np.clip(np.einsum("pk,sk->ps", points, d) - np.einsum("sk,sk->s", a, d), 0, None)
    t = np.minimum(t / np.einsum("sk,sk->s", d, d), 1.0)
    closest = a[None] + t[:, :, None] * d[None]
    return np.min(np.linalg.norm(points[:, None, :] - closest, axis=2), axis=1)


def test_noise_free_pair_lies_on_the_walls():
    world = rooms_world()
    pose_ref, pose_cur = np.array([5.0, 2.5, 0.3]), np.array([5.2, 2.4, 0.45])
    pair = simulated_scan_pair(
        world, pose_ref, pose_cur, BEAMS, 20.0, 0.0, np.random.default_rng(0)
    )
    np.testing.assert_allclose(pair.T_ref_cur, between(pose_ref, pose_cur))
    for pts, pose in ((pair.reference, pose_ref), (pair.current, pose_cur)):
        assert pts.shape == (BEAMS.size, 2)  # a closed room: every beam returns
        assert _distance_to_walls(transform_points(pose, pts), world.segments).max() < 1e-9


def test_random_pairs_have_the_stated_motion_and_repeat_with_the_seed():
    kw = dict(beam_angles=BEAMS, max_range=20.0, range_sigma=0.01, motion=(0.3, 0.2))
    a = random_scan_pairs(rooms_world(), 5, np.random.default_rng(7), **kw)
    b = random_scan_pairs(rooms_world(), 5, np.random.default_rng(7), **kw)
    for p, q in zip(a, b, strict=True):
        assert np.isclose(np.hypot(p.T_ref_cur[0], p.T_ref_cur[1]), 0.3)
        assert np.isclose(abs(p.T_ref_cur[2]), 0.2)
        np.testing.assert_array_equal(p.current, q.current)


def test_corridor_has_two_parallel_walls():
    seg = corridor_world(100.0, 3.0).segments
    np.testing.assert_allclose(seg[:, :, 1], [[-1.5, -1.5], [1.5, 1.5]])
    np.testing.assert_allclose(seg[:, :, 0], [[-50.0, 50.0], [-50.0, 50.0]])
