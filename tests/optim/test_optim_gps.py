"""The GPS factor (:mod:`slamkit.optim.gps`): hand value, analytic Jacobians against central
finite differences on the manifold, the gauge it fixes, and the fix weights."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.errors import ConfigError
from slamkit.optim import GraphProblem, factors
from slamkit.optim.data import EdgeSet, GraphData
from slamkit.optim.gps import GpsWeighting, gps_error, gps_weights, reweight, whitened_squares

H = 1e-6


def test_gps_error_hand_value() -> None:
    """Pose (1, 2, 90°), lever arm (0.5, 0.25): the antenna is at (1 - 0.25, 2 + 0.5)."""
    x = np.array([[1.0, 2.0, np.pi / 2]])
    o = np.array([[0.5, 0.25]])
    z = np.array([[0.7, 2.6]])
    e, _, _ = gps_error(x, o, z)
    np.testing.assert_allclose(e[0], [0.75 - 0.7, 2.5 - 2.6], atol=1e-12)


def test_gps_jacobians_match_finite_differences() -> None:
    rng = np.random.default_rng(3)
    n = 50
    x = rng.normal(size=(n, 3)) * [10.0, 10.0, 2.0]
    o = rng.normal(size=(n, 2)) * 2.0
    z = rng.normal(size=(n, 2)) * 10.0
    _, Ji, Jo = gps_error(x, o, z)
    fd_i = np.empty((n, 2, 3))
    for k in range(3):
        d = np.zeros((n, 3))
        d[:, k] = H
        plus = gps_error(factors.retract_poses(x, d), o, z)[0]
        minus = gps_error(factors.retract_poses(x, -d), o, z)[0]
        fd_i[:, :, k] = (plus - minus) / (2 * H)
    fd_o = np.empty((n, 2, 2))
    for k in range(2):
        d = np.zeros((n, 2))
        d[:, k] = H
        fd_o[:, :, k] = (gps_error(x, o + d, z)[0] - gps_error(x, o - d, z)[0]) / (2 * H)
    np.testing.assert_allclose(Ji, fd_i, atol=1e-7)
    np.testing.assert_allclose(Jo, fd_o, atol=1e-7)


def _two_pose_graph(fixed: bool) -> GraphData:
    """Two poses joined by odometry, each with one GPS fix; lever arm id 100."""
    gps = EdgeSet(
        "gps",
        np.array([0, 1]),
        np.array([100, 100]),
        np.array([[0.0, 0.0], [1.0, 0.0]]),
        np.tile(np.eye(2), (2, 1, 1)),
        np.zeros(2, dtype=np.int64),
    )
    odo = EdgeSet(
        "se2",
        np.array([0]),
        np.array([1]),
        np.array([[1.0, 0.0, 0.0]]),
        np.eye(3)[None],
        np.zeros(1, dtype=np.int64),
    )
    return GraphData(
        dim=2,
        pose_ids=np.array([0, 1]),
        poses=np.zeros((2, 3)),
        landmark_ids=np.array([100]),
        landmarks=np.zeros((1, 2)),
        edges=(odo, gps),
        fixed_ids=np.array([0]) if fixed else np.zeros(0, dtype=np.int64),
    )


def test_gps_edges_fix_the_gauge() -> None:
    """GPS fixes are absolute: no pose is anchored; the whitened error of the linearisation
    at the truth is zero."""
    problem = GraphProblem.from_data(_two_pose_graph(fixed=False))
    assert not problem.anchored_first and not problem.fixed.any()
    lin = problem.linearize(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), np.zeros((1, 2)))
    assert lin.cost == pytest.approx(0.0, abs=1e-20)
    assert problem.n == 3 * 2 + 2


def test_whitened_squares_and_weights() -> None:
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, np.pi / 2]])
    fixes = np.array([[1.0, 0.0], [0.0, 4.0]])  # the second is 3 m off the antenna (0, 1)
    info = np.tile(np.eye(2) / 0.25, (2, 1, 1))  # σ = 0.5 m
    s = whitened_squares(poses, np.array([1.0, 0.0]), fixes, info)
    np.testing.assert_allclose(s, [0.0, 36.0])
    np.testing.assert_array_equal(gps_weights(GpsWeighting("gate", 9.21), s), [1.0, 0.0])
    np.testing.assert_allclose(gps_weights(GpsWeighting("cauchy", 3.0), s), [1.0, 1 / 5])
    edges = reweight(_two_pose_graph(False).edges[1], info, np.array([1.0, 0.0]))
    assert edges.information[1, 0, 0] == pytest.approx(4e-12)


def test_weighting_rejects_bad_settings() -> None:
    with pytest.raises(ConfigError, match="unknown name"):
        GpsWeighting("tukey")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="width"):
        GpsWeighting("gate", -1.0)
