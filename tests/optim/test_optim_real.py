"""The optimiser on the public 2D pose graphs: SE-Sync's certified optima F* (Rosen et al.,
IJRR 2019, Table 1) to four significant digits, and agreement of the methods on the g2o χ²."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slamkit.io.posegraph import read_graph
from slamkit.optim import (
    GraphProblem,
    OptimizerConfig,
    StoppingConfig,
    g2o_chi2,
    marginal_covariances,
    optimize,
    sesync_objective,
    spanning_tree_initialization,
)

pytestmark = pytest.mark.realdata


def _read(data_root: Path, name: str):
    path = data_root / "posegraph2d" / name
    if not path.exists():
        pytest.skip(f"{path} not found")
    return read_graph(path)


@pytest.mark.parametrize(
    ("name", "f_star", "init"),
    [
        ("intel.g2o", 5.235e1, "chordal"),
        ("CSAIL.g2o", 3.170e1, "chordal"),
        ("intel.g2o", 5.235e1, "vertices"),
    ],
)
def test_sesync_optimum_to_four_digits(
    data_root: Path, name: str, f_star: float, init: str
) -> None:
    graph = _read(data_root, name)
    cfg = OptimizerConfig(objective="sesync", initialization=init)  # type: ignore[arg-type]
    res = optimize(graph, cfg)
    assert res.converged
    assert float(f"{res.cost:.4g}") == f_star
    assert sesync_objective(graph, res.poses) == pytest.approx(res.cost, rel=1e-12)


def test_manhattan_sesync_minimum(data_root: Path) -> None:
    """manhattan: our minimum of F is 6431.39, just below the published F* = 6.432e3.

    The objective is SE-Sync's own: its reader (``read_g2o_file``, C++ and MATLAB) sets
    ``κ = I33`` and ``τ = 2 / tr((I_tt)⁻¹)`` as we do, and manhattan's information matrices
    have ``I13 = I23 = 0``, so "which block is inverted" cannot matter. F evaluated by an
    independent loop over the edges agrees to 1e-13; LM from the chordal and from the odometry
    start reach 6431.391387 (to 1e-12 relative, max |gradient| 6e-6). The published value
    rounds SE-Sync's returned solution, which stops at a relative decrease of 1e-5 and a
    gradient norm of 1e-2 (its defaults): 6.432e3 means F ≥ 6431.5, within 1.7e-5 of the
    minimum. So the fourth digit differs by one while the value is the lower (better) one.
    """
    graph = _read(data_root, "manhattan.g2o")
    es = graph.edges[0]
    assert np.all(es.information[:, :2, 2] == 0.0)
    res = optimize(graph, OptimizerConfig(objective="sesync", initialization="chordal"))
    assert res.converged
    assert res.cost == pytest.approx(6431.391, abs=0.01)
    assert res.cost < 6431.5  # below the rounding interval of the published 6.432e3
    assert res.cost > 6432 * (1 - 1e-4)


def test_intel_methods_agree_on_g2o_chi2(data_root: Path) -> None:
    graph = _read(data_root, "intel.g2o")
    costs = {}
    for method in ("gn", "lm", "dogleg"):
        cfg = OptimizerConfig(
            solver=method,  # type: ignore[arg-type]
            initialization="vertices",
            stopping=StoppingConfig(relative_tolerance=1e-9),
        )
        res = optimize(graph, cfg)
        assert res.converged, res.reason
        costs[method] = res.cost
        assert g2o_chi2(graph, res.poses) == pytest.approx(res.cost, rel=1e-12)
    assert costs["gn"] == pytest.approx(45.0047, rel=1e-5)  # from the file's vertices
    assert costs["lm"] == pytest.approx(costs["gn"], rel=1e-8)
    assert costs["dogleg"] == pytest.approx(costs["gn"], rel=1e-8)
    assert res.initial_cost == pytest.approx(551.736, rel=1e-5)


def test_csail_without_vertices_starts_from_odometry(data_root: Path) -> None:
    graph = _read(data_root, "CSAIL.g2o")
    assert graph.poses.shape[0] == 0
    problem = GraphProblem.from_data(graph)
    start = spanning_tree_initialization(problem)
    np.testing.assert_array_equal(start[0], [0.0, 0.0, 0.0])  # the anchored first pose
    # The tree is the odometry chain: consecutive poses differ by their edge's measurement.
    es = graph.edges[0]
    odo = np.flatnonzero(es.j == es.i + 1)
    assert odo.shape[0] == problem.pose_ids.shape[0] - 1
    res = optimize(graph)
    assert res.converged and res.cost == pytest.approx(40.5551, rel=1e-5)
    marg = marginal_covariances(graph, res, pose_ids=[0, 1, 500])
    np.testing.assert_array_equal(marg.pose_covariances[0], 0.0)
    sd = np.sqrt(np.diagonal(marg.pose_covariances[1:], axis1=1, axis2=2))
    assert np.all(sd > 0) and np.all(sd[:, :2] < 5.0)
    assert np.all(sd[1, :2] > 3 * sd[0, :2])  # far from the anchor, far more uncertain


def test_toro_graph_with_equivalences(data_root: Path) -> None:
    graph = _read(data_root, "w100.graph")
    assert graph.equivalences.shape == (40, 2)
    res = optimize(graph)
    assert res.converged and res.cost == pytest.approx(1.036176, rel=1e-5)
    rows = {int(k): r for r, k in enumerate(res.pose_ids)}
    for a, b in graph.equivalences:
        np.testing.assert_array_equal(res.poses[rows[int(a)]], res.poses[rows[int(b)]])
