"""Bad graphs get typed errors that name the edge (file and line) or the variables."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.errors import (
    CovarianceError,
    GeometryError,
    InputError,
    NonFiniteError,
    ShapeError,
)
from slamkit.optim import (
    EdgeSet,
    GraphData,
    GraphProblem,
    OptimizerConfig,
    cholmod_available,
    marginal_covariances,
    optimize,
)


def _graph(
    i=(0, 1, 2),
    j=(1, 2, 0),
    info: np.ndarray | None = None,
    z: np.ndarray | None = None,
    pose_ids=(0, 1, 2),
    extra: tuple[EdgeSet, ...] = (),
    fixed=(),
) -> GraphData:
    n = len(i)
    meas = np.tile([1.0, 0.0, 2 * np.pi / 3], (n, 1)) if z is None else z
    inf = np.tile(np.eye(3) * 10.0, (n, 1, 1)) if info is None else info
    edges = EdgeSet(
        "se2",
        np.array(i, dtype=np.int64),
        np.array(j, dtype=np.int64),
        meas,
        inf,
        np.arange(10, 10 + n, dtype=np.int64),  # as if read from lines 10, 11, ...
    )
    ids = np.array(pose_ids, dtype=np.int64)
    # A start near the equilateral triangle the measurements describe (all-zero poses would be
    # a stationary point by symmetry).
    a = 2 * np.pi / 3 * np.arange(ids.shape[0])
    start = np.stack([np.cos(a) * 0.6 + 0.1, np.sin(a) * 0.5, a + np.pi / 2 + 0.1], -1)
    return GraphData(
        dim=2,
        pose_ids=ids,
        poses=start,
        edges=(edges, *extra),
        fixed_ids=np.array(fixed, dtype=np.int64),
        family="g2o",
        source="loop.g2o",
    )


def test_a_valid_triangle_optimises() -> None:
    res = optimize(_graph())
    assert res.converged and res.cost < 1e-12


def test_edge_to_missing_vertex_names_the_line() -> None:
    with pytest.raises(InputError, match=r"loop\.g2o:11: se2 edge 1 → 7: pose 7 has no vertex"):
        optimize(_graph(j=(1, 7, 0)))


def test_non_positive_definite_information_names_the_line() -> None:
    info = np.tile(np.eye(3) * 10.0, (3, 1, 1))
    info[2, 1, 1] = -1.0
    with pytest.raises(CovarianceError, match=r"loop\.g2o:12: se2 edge 2 → 0: .*not positive"):
        optimize(_graph(info=info))


def test_asymmetric_information_is_rejected() -> None:
    info = np.tile(np.eye(3) * 10.0, (3, 1, 1))
    info[0, 0, 1] = 3.0
    with pytest.raises(CovarianceError, match=r"loop\.g2o:10: .*not symmetric"):
        optimize(_graph(info=info))


def test_nan_measurement_names_the_line() -> None:
    z = np.tile([1.0, 0.0, 2 * np.pi / 3], (3, 1))
    z[1, 0] = np.nan
    with pytest.raises(NonFiniteError, match=r"loop\.g2o:11: se2 edge 1 → 2: NaN"):
        optimize(_graph(z=z))


def test_nan_vertex_and_bad_shapes() -> None:
    g = _graph()
    poses = g.poses.copy()
    poses[2, 1] = np.inf
    with pytest.raises(NonFiniteError, match="pose 2"):
        optimize(GraphData(dim=2, pose_ids=g.pose_ids, poses=poses, edges=g.edges))
    with pytest.raises(ShapeError, match="measurement"):
        optimize(_graph(z=np.zeros((3, 2))))


def test_in_memory_edges_are_named_by_index() -> None:
    g = _graph(j=(1, 9, 0))
    es = g.edges[0]
    bare = EdgeSet("se2", es.i, es.j, es.measurement, es.information, np.zeros(3, np.int64))
    with pytest.raises(InputError, match=r"se2 edge 1 → 9 \(#1 of its set\): pose 9 has no vertex"):
        optimize(GraphData(dim=2, pose_ids=g.pose_ids, poses=g.poses, edges=(bare,)))


def test_self_loop_is_rejected() -> None:
    with pytest.raises(InputError, match="to itself"):
        optimize(_graph(j=(1, 2, 2)))


def test_no_gauge_says_so_and_names_the_poses() -> None:
    with pytest.raises(GeometryError, match=r"gauge is not fixed.*pose 0, pose 1, pose 2 are"):
        optimize(_graph(), OptimizerConfig(gauge="none"))
    # With a fixed pose the same setting is fine.
    assert optimize(_graph(fixed=(1,)), OptimizerConfig(gauge="none")).cost < 1e-12
    with pytest.raises(InputError, match="gauge: expected"):
        GraphProblem.from_data(_graph(), gauge="first")  # type: ignore[arg-type]


def _triangle_3d(prior: bool) -> GraphData:
    """The triangle of :func:`_graph` lifted to SE(3) (turns about z), optionally with an
    ``se3_prior`` on pose 2."""
    g = _graph()
    es = g.edges[0]
    th = es.measurement[:, 2]
    z = np.zeros((3, 7))
    z[:, 0], z[:, 1] = es.measurement[:, 0], es.measurement[:, 1]
    z[:, 3], z[:, 6] = np.cos(th / 2), np.sin(th / 2)
    edges = [EdgeSet("se3", es.i, es.j, z, np.tile(np.eye(6) * 10.0, (3, 1, 1)), es.lines)]
    start = np.zeros((3, 7))
    start[:, :2] = g.poses[:, :2]
    start[:, 3], start[:, 6] = np.cos(g.poses[:, 2] / 2), np.sin(g.poses[:, 2] / 2)
    if prior:
        p = start[2:3].copy()
        edges.append(
            EdgeSet(
                "se3_prior", np.array([2]), np.array([-1]), p, np.eye(6)[None] * 1e3, es.lines[:1]
            )
        )
    return GraphData(dim=3, pose_ids=g.pose_ids, poses=start, edges=tuple(edges))


def test_se3_prior_fixes_the_gauge() -> None:
    """A prior fixes the gauge in 3D as in 2D: no pose is anchored, and gauge="none" works."""
    with_prior = _triangle_3d(prior=True)
    problem = GraphProblem.from_data(with_prior, gauge="none")
    assert not problem.anchored_first and problem.n == 18  # all three poses free
    res = optimize(with_prior, OptimizerConfig(gauge="none"))
    assert res.converged and not res.anchored_first and res.cost < 1e-12
    assert not GraphProblem.from_data(with_prior).anchored_first  # the default agrees
    with pytest.raises(GeometryError, match=r"gauge is not fixed.*pose 0, pose 1, pose 2"):
        GraphProblem.from_data(_triangle_3d(prior=False), gauge="none")
    assert GraphProblem.from_data(_triangle_3d(prior=False)).anchored_first


def test_duplicate_ids_name_the_id() -> None:
    g = _graph(pose_ids=(0, 1, 1))
    with pytest.raises(InputError, match=r"pose_ids: pose 1 appears 2 times \(rows 1, 2\)"):
        GraphProblem.from_data(g)
    lm = GraphData(
        dim=2,
        pose_ids=g.pose_ids[:2],
        poses=g.poses[:2],
        landmark_ids=np.array([4, 9, 4], dtype=np.int64),
        landmarks=np.zeros((3, 2)),
        edges=(),
    )
    with pytest.raises(InputError, match=r"landmark 4 appears 2 times"):
        GraphProblem.from_data(lm)


def test_disconnected_graph_names_the_variables() -> None:
    g = _graph(i=(0, 1, 3), j=(1, 2, 4), pose_ids=(0, 1, 2, 3, 4))
    with pytest.raises(GeometryError, match=r"disconnected.*pose 3, pose 4"):
        optimize(g)


def test_isolated_landmark_and_unknown_landmark() -> None:
    lm_edges = EdgeSet(
        "se2_xy",
        np.array([0], dtype=np.int64),
        np.array([50], dtype=np.int64),
        np.array([[1.0, 1.0]]),
        np.eye(2)[None] * 5.0,
        np.array([20], dtype=np.int64),
    )
    g = _graph(extra=(lm_edges,))
    with_vertices = GraphData(
        dim=2,
        pose_ids=g.pose_ids,
        poses=g.poses,
        landmark_ids=np.array([50, 51], dtype=np.int64),
        landmarks=np.zeros((2, 2)),
        edges=g.edges,
        source="loop.g2o",
    )
    with pytest.raises(GeometryError, match="landmark 51"):
        GraphProblem.from_data(with_vertices)
    only_51 = GraphData(
        dim=2,
        pose_ids=g.pose_ids,
        poses=g.poses,
        landmark_ids=np.array([51], dtype=np.int64),
        landmarks=np.zeros((1, 2)),
        edges=g.edges,
        source="loop.g2o",
    )
    with pytest.raises(InputError, match=r"loop\.g2o:20: se2_xy edge 0 → 50: landmark 50"):
        GraphProblem.from_data(only_51)


def test_singular_normal_equations_raise_geometry_error() -> None:
    """A landmark seen by one bearing only: its range is not determined (GN, no damping)."""
    bearing = EdgeSet(
        "bearing",
        np.array([0], dtype=np.int64),
        np.array([7], dtype=np.int64),
        np.array([[0.3]]),
        np.eye(1)[None] * 100.0,
        np.zeros(1, dtype=np.int64),
    )
    g = _graph(extra=(bearing,))
    g = GraphData(
        dim=2,
        pose_ids=g.pose_ids,
        poses=g.poses,
        landmark_ids=np.array([7], dtype=np.int64),
        landmarks=np.array([[2.0, 1.0]]),
        edges=g.edges,
    )
    solvers = ["dense", "superlu"] + (["cholmod"] if cholmod_available() else [])
    for solver in solvers:
        with pytest.raises(GeometryError, match=r"singular.*landmark 7 is not determined"):
            optimize(g, OptimizerConfig(solver="gn", linear_solver=solver))  # type: ignore[arg-type]
    # The dense back-end eliminates in variable order: the landmark's pivot is the one that fails.
    with pytest.raises(GeometryError, match=r"failed at landmark 7 \(y\)"):
        optimize(g, OptimizerConfig(solver="gn", linear_solver="dense"))
    with pytest.raises(GeometryError, match=r"marginals: .*landmark 7"):
        res = optimize(g, OptimizerConfig(solver="lm"))  # damping keeps LM going
        marginal_covariances(g, res, landmark_ids=[7])


def test_singular_pivot_is_named_in_the_original_order() -> None:
    """Pose 3 hangs off the triangle by one range reading to a landmark fixed by the triangle:
    its heading is free. Every back-end names pose 3 (its block is singular); the pivot that
    fails is mapped back through the fill-reducing permutation to a column of pose 3 (dense
    and CHOLMOD)."""
    xy = EdgeSet(
        "se2_xy",
        np.array([0, 1], dtype=np.int64),
        np.array([7, 7], dtype=np.int64),
        np.array([[1.0, 1.0], [0.5, 1.5]]),
        np.tile(np.eye(2) * 5.0, (2, 1, 1)),
        np.zeros(2, dtype=np.int64),
    )
    rng_edge = EdgeSet(
        "range",
        np.array([3], dtype=np.int64),
        np.array([7], dtype=np.int64),
        np.array([[2.0]]),
        np.eye(1)[None] * 5.0,
        np.zeros(1, dtype=np.int64),
    )
    g = _graph(extra=(xy, rng_edge), pose_ids=(0, 1, 2, 3))
    g = GraphData(
        dim=2,
        pose_ids=g.pose_ids,
        poses=np.vstack([g.poses[:3], [[3.0, 2.0, 0.4]]]),
        landmark_ids=np.array([7], dtype=np.int64),
        landmarks=np.array([[1.0, 1.5]]),
        edges=g.edges,
    )
    solvers = ["dense", "superlu"] + (["cholmod"] if cholmod_available() else [])
    for solver in solvers:
        with pytest.raises(GeometryError, match=r"pose 3 is not determined") as info:
            optimize(g, OptimizerConfig(solver="gn", linear_solver=solver))  # type: ignore[arg-type]
        if solver != "superlu":  # SuperLU reports an exactly singular factor without a column
            assert "failed at pose 3 (" in str(info.value), (solver, str(info.value))


def test_edge_kind_must_match_the_dimension() -> None:
    g = _graph()
    g3 = GraphData(
        dim=3, pose_ids=g.pose_ids, poses=np.tile([0.0, 0, 0, 1, 0, 0, 0], (3, 1)), edges=g.edges
    )
    with pytest.raises(InputError, match="'se2' is not supported in a 3D graph"):
        optimize(g3)


def test_huge_information_is_refused_without_overflow_warnings(tmp_path):
    import warnings

    from slamkit.errors import SlamkitError
    from slamkit.io.posegraph import read_graph
    from slamkit.optim import optimize

    path = tmp_path / "big.g2o"
    path.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1e200 0 0 1e200 0 1e200\n"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any RuntimeWarning fails the test
        with pytest.raises(SlamkitError, match=r"big\.g2o:3"):
            optimize(read_graph(path))
