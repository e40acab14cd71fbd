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
from slamkit.optim import EdgeSet, GraphData, GraphProblem, OptimizerConfig, optimize


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


def test_no_gauge_says_so() -> None:
    with pytest.raises(GeometryError, match="gauge is not fixed"):
        optimize(_graph(), OptimizerConfig(gauge="none"))
    # With a fixed pose the same setting is fine.
    assert optimize(_graph(fixed=(1,)), OptimizerConfig(gauge="none")).cost < 1e-12


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
    with pytest.raises(GeometryError, match="singular"):
        optimize(g, OptimizerConfig(method="gn", linear_solver="dense"))


def test_edge_kind_must_match_the_dimension() -> None:
    g = _graph()
    g3 = GraphData(
        dim=3, pose_ids=g.pose_ids, poses=np.tile([0.0, 0, 0, 1, 0, 0, 0], (3, 1)), edges=g.edges
    )
    with pytest.raises(InputError, match="'se2' is not supported in a 3D graph"):
        optimize(g3)
