"""The grid nearest-neighbour search against the KD-tree it stands in for, and the compiled
ICP terms against their NumPy twin: equal to the last bit, not to a tolerance."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from slamkit.backend import AVAILABLE, SEAM, Backend
from slamkit.errors import MatchError
from slamkit.scanmatch.nearest import NearestGrid, grid_nearest
from slamkit.scanmatch.normal_icp import NormalCloud, normal_icp
from slamkit.scanmatch.normal_terms import pair_terms, pair_terms_numpy
from slamkit.scanmatch.point_map import PointMap
from slamkit.sim import rooms_world
from slamkit.sim.scans import random_scan_pairs

BEAMS = np.deg2rad(np.arange(-90.0, 90.5, 1.0))
needs_numba = pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")


def _kdtree(points: np.ndarray, x: np.ndarray, bound: float) -> np.ndarray:
    return cKDTree(points, leafsize=8).query(x, k=1, distance_upper_bound=bound)[1]


def _grid(points: np.ndarray, cell: float) -> NearestGrid:
    return NearestGrid(points, cell)


@pytest.mark.parametrize("offset", [0.0, 1e5])
@pytest.mark.parametrize("cell", [0.05, 0.5, 3.0])
def test_grid_returns_the_kdtrees_index_on_walls_and_scatter(offset: float, cell: float) -> None:
    """Points along walls (as in a map) and scattered ones, queries inside and outside the
    box, several bounds and cell sizes (smaller and larger than the bound), coordinates near
    zero and far from it."""
    rng = np.random.default_rng(11)
    t = rng.uniform(0.0, 10.0, 400)
    walls = np.column_stack([t, np.where(t > 5.0, 3.0, 0.0) + 0.01 * rng.standard_normal(400)])
    points = np.vstack([walls, rng.uniform(-2.0, 12.0, (300, 2))]) + offset
    x = rng.uniform(-4.0, 14.0, (2000, 2)) + offset
    grid = _grid(points, cell)
    for bound in (0.05, 0.2, 0.5, 2.0):
        np.testing.assert_array_equal(grid.query(x, bound), _kdtree(points, x, bound))


def test_the_bound_is_strict_and_squared_as_the_kdtrees() -> None:
    """A point at exactly the bound is no pair (the squared distance equal to the squared
    bound), one a rounding nearer is."""
    points = np.array([[0.0, 0.0], [10.0, 0.0]])
    x = np.array([[0.5, 0.0], [0.0, 0.4999999999999999], [0.2, 0.0], [10.0, 0.2]])
    for bound in (0.5, 0.2):
        got = _grid(points, bound).query(x, bound)
        np.testing.assert_array_equal(got, _kdtree(points, x, bound))
    assert list(_grid(points, 0.5).query(x[:2], 0.5)) == [2, 0]


def test_ties_are_left_to_the_kdtree() -> None:
    """Several points at exactly the least distance: the kernel flags the query and the
    KD-tree's own choice is returned."""
    ring = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [3.0, 3.0]])
    x = np.array([[0.0, 0.0], [2.9, 3.0], [0.5, 0.0]])
    grid = _grid(ring, 0.7)
    if AVAILABLE:
        out = np.empty(3, dtype=np.intp)
        tied = grid_nearest(grid.cells, grid.geometry, x, 2.0, out)
        assert tied and list(out) == [-1, 4, 0]
    np.testing.assert_array_equal(grid.query(x, 2.0), _kdtree(ring, x, 2.0))


def test_empty_and_far_queries_find_nothing() -> None:
    x = np.array([[0.0, 0.0], [100.0, -100.0]])
    assert list(_grid(np.zeros((0, 2)), 0.5).query(x, 0.5)) == [0, 0]
    points = np.array([[1.0, 1.0], [1.2, 1.1]])
    assert list(_grid(points, 0.5).query(x, 0.5)) == [2, 2]


def test_a_sparse_box_gets_larger_cells() -> None:
    """Two points 1 km apart: the cell grows to keep the table small, answers unchanged."""
    points = np.array([[0.0, 0.0], [1000.0, 1000.0]])
    grid = _grid(points, 0.1)
    assert grid.shape[0] * grid.shape[1] <= 16 * 2 + 64 + 2 * 10
    x = np.array([[0.05, 0.0], [999.9, 1000.0], [500.0, 500.0]])
    np.testing.assert_array_equal(grid.query(x, 0.5), _kdtree(points, x, 0.5))


def test_the_numpy_path_is_the_kdtree() -> None:
    rng = np.random.default_rng(2)
    points = rng.uniform(0.0, 5.0, (200, 2))
    x = rng.uniform(0.0, 5.0, (300, 2))
    grid = _grid(points, 0.5)
    fast = grid.query(x, 0.3)
    with SEAM.use(Backend.NUMPY):
        slow = grid.query(x, 0.3)
    np.testing.assert_array_equal(fast, slow)
    np.testing.assert_array_equal(slow, _kdtree(points, x, 0.3))


@needs_numba
@pytest.mark.parametrize("n", [5, 10, 11, 180, 181])
def test_compiled_pair_terms_are_numpys_to_the_bit(n: int) -> None:
    """Random maps and scans, odd and even pair counts (the median's two cases), some
    points unpaired; fewer pairs than the minimum give the stamp alone."""
    rng = np.random.default_rng(n)
    for _ in range(20):
        m = 60
        points = rng.uniform(-5.0, 5.0, (m, 2))
        ang = rng.uniform(-np.pi, np.pi, m)
        normals = np.column_stack([np.cos(ang), np.sin(ang)])
        q = rng.uniform(-5.0, 5.0, (n, 2))
        theta = float(rng.uniform(-np.pi, np.pi))
        moved = q @ np.array([[np.cos(theta), np.sin(theta)], [-np.sin(theta), np.cos(theta)]])
        moved += rng.uniform(-1.0, 1.0, 2)
        j = rng.integers(0, m + m // 3, n)  # >= m: unpaired
        j = np.minimum(j, m)
        for min_pairs in (1, n + 1):
            a = pair_terms(moved, q, j, points, normals, theta, 1.5, 0.005, min_pairs)
            b = pair_terms_numpy(moved, q, j, points, normals, theta, 1.5, 0.005, min_pairs)
            assert a.n_pairs == b.n_pairs and a.stamp == b.stamp and a.sigma == b.sigma
            for u, v in zip(a[2:7], b[2:7], strict=True):
                assert u.shape == v.shape and np.array_equal(u, v)


@needs_numba
def test_normal_icp_is_the_same_with_and_without_the_kernels() -> None:
    """Whole matches, with and without a prior: the same pose and covariance to the bit
    (or the same refusal)."""
    rng = np.random.default_rng(5)
    pairs = random_scan_pairs(
        rooms_world(), 8, rng, beam_angles=BEAMS, max_range=12.0, range_sigma=0.01
    )
    prior = np.diag([1e2, 1e2, 1e3])
    for pair in pairs:
        m = PointMap(0.05)
        m.insert(np.zeros(3), pair.reference)
        points, normals = m.arrays()
        start = pair.T_ref_cur + np.array([0.05, -0.04, 0.03])
        for lam in (None, prior):
            runs = []
            for numpy_only in (False, True):
                cloud = NormalCloud.build(points, normals)  # no grid carried over
                try:
                    if numpy_only:
                        with SEAM.use(Backend.NUMPY):
                            r = normal_icp(cloud, pair.current, start, prior_information=lam)
                    else:
                        r = normal_icp(cloud, pair.current, start, prior_information=lam)
                    runs.append((r.pose.tobytes(), r.cov.tobytes(), r.iterations))
                except MatchError as exc:
                    runs.append(exc.reason)
            assert runs[0] == runs[1]


def test_the_prior_check_is_allclose_and_eigvalsh() -> None:
    """Priors that are clearly definite, nearly singular, singular, indefinite, slightly
    or clearly asymmetric: normal_icp refuses exactly those that the plain check
    ``not allclose(Λ, Λᵀ) or eigvalsh(sym Λ)[0] < 0`` refuses."""
    from slamkit.errors import CovarianceError

    rng = np.random.default_rng(9)
    t = np.linspace(0.0, 2.0 * np.pi, 60, endpoint=False)
    ring = np.column_stack([3.0 * np.cos(t), 2.0 * np.sin(t)])
    cloud = NormalCloud.build(ring, ring / np.linalg.norm(ring, axis=1)[:, None])
    cases = []
    for _ in range(60):
        b = rng.standard_normal((3, 3))
        eig = rng.choice([1e-20, 1e-8, 0.0, -1e-14, -1.0, 1.0, 1e4], 3)
        lam = b @ np.diag(eig) @ b.T
        cases += [lam, lam + rng.choice([0.0, 1e-9, 1e-3]) * rng.standard_normal((3, 3))]
    cases += [np.zeros((3, 3)), np.diag([1e2, 1e2, 1e3]), -np.eye(3)]
    refused = 0
    for lam in cases:
        plain = not np.allclose(lam, lam.T) or np.linalg.eigvalsh(0.5 * (lam + lam.T))[0] < 0
        try:
            normal_icp(cloud, ring[::3], (0.0, 0.0, 0.0), prior_information=lam)
            raised = False
        except CovarianceError:
            raised = True
        except (MatchError, np.linalg.LinAlgError):
            raised = False
        assert raised == plain
        refused += raised
    assert 0 < refused < len(cases)


def test_a_cloud_with_its_grids_pickles() -> None:
    """A cloud that has answered queries (its grid and KD-tree built) pickles and answers
    the same after."""
    import pickle

    rng = np.random.default_rng(4)
    points = rng.uniform(0.0, 5.0, (100, 2))
    cloud = NormalCloud.build(points, np.tile([1.0, 0.0], (100, 1)))
    x = rng.uniform(0.0, 5.0, (50, 2))
    before = cloud.nearest(x, 0.4)
    assert cloud.tree.n == 100
    again = pickle.loads(pickle.dumps(cloud))
    np.testing.assert_array_equal(again.nearest(x, 0.4), before)
