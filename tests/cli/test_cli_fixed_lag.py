"""``slamkit optimize FILE --window L``: a graph file streamed through the fixed-lag smoother;
the written graph, online and window estimates agree with the metrics, dropped loop closures
are counted, and batch-only options are refused in one line."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.geometry import pose2
from slamkit.io.posegraph import read_graph, write_graph
from slamkit.optim import EdgeSet, GraphData, g2o_chi2

runner = CliRunner()


def _square_laps(tmp_path: Path) -> Path:
    """Three laps of a 4-pose square (exact odometry and a loop closure one lap back),
    written as g2o."""
    n = 13
    truth = np.zeros((n, 3))
    for k in range(1, n):
        truth[k] = pose2.compose(truth[k - 1], np.array([2.0, 0.0, np.pi / 2]))
    i = np.array(list(range(n - 1)) + list(range(n - 4)))
    j = np.array(list(range(1, n)) + list(range(4, n)))
    z = pose2.compose(pose2.between(truth[i], truth[j]), np.array([0.01, -0.02, 0.005]))
    info = np.broadcast_to(np.diag([100.0, 100.0, 400.0]), (i.shape[0], 3, 3)).copy()
    es = EdgeSet("se2", i, j, z, info, np.zeros(i.shape[0], dtype=np.int64))
    path = tmp_path / "laps.g2o"
    write_graph(GraphData(dim=2, pose_ids=np.arange(n), poses=truth, edges=(es,)), path)
    return path


def test_window_writes_the_smoother_outputs(tmp_path: Path) -> None:
    src = _square_laps(tmp_path)
    out = tmp_path / "out"
    res = runner.invoke(app, ["optimize", str(src), "--window", "3", "--out", str(out)])
    assert res.exit_code == 0, res.output
    m = json.loads((out / "metrics.json").read_text())
    assert sorted(os.listdir(out)) == [
        "config.json", "graph.png", "metrics.json", "online.csv", "optimized.g2o", "window.csv",
    ]  # fmt: skip
    # Window 3 cannot hold a loop 4 poses back: the closures i → i + 4 with i ≥ 1 are dropped
    # (i = 0 is the anchor's); their file lines are listed.
    assert m["poses"] == 13 and m["steps"] == 13 and m["window"] == 3
    assert m["dropped_edges"]["count"] == 8 == len(m["dropped_edges"]["first"])
    assert all(f.startswith(f"{src}:") for f in m["dropped_edges"]["first"])
    assert m["converged"] and m["anchored_first_pose"]
    online = np.loadtxt(out / "online.csv", delimiter=",", skiprows=1)
    window = np.loadtxt(out / "window.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(online[:, 0], np.arange(10))
    np.testing.assert_array_equal(online[1:, 4], np.arange(1, 10) + 4)  # pose k leaves at k + 4
    np.testing.assert_array_equal(window[:, 0], [10, 11, 12])
    graph = read_graph(out / "optimized.g2o")
    np.testing.assert_allclose(graph.poses[:10], online[:, 1:4], atol=1e-12)
    np.testing.assert_allclose(graph.poses[10:], window[:, 1:4], atol=1e-12)
    assert g2o_chi2(graph, graph.poses) == pytest.approx(m["chi2_final"], rel=1e-9)
    assert m["chi2_final"] < m["chi2_initial"]
    assert json.loads((out / "config.json").read_text())["fixed_lag"]["window"] == 3


def test_window_refuses_batch_options_in_one_line(tmp_path: Path) -> None:
    src = _square_laps(tmp_path)
    out = tmp_path / "out"
    res = runner.invoke(
        app, ["optimize", str(src), "--window", "3", "--robust", "huber", "--out", str(out)]
    )
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert "--robust applies to the batch optimiser only" in lines[0]
    assert not out.exists()


def _landmark_file(tmp_path: Path) -> Path:
    """A 12-pose arc among 6 landmarks, odometry and landmark-in-robot-frame readings
    (``EDGE_SE2_XY``) with small fixed errors, written as g2o (vertices at dead reckoning)."""
    n = 12
    step = np.array([1.0, 0.0, 0.2])
    truth = np.zeros((n, 3))
    for k in range(1, n):
        truth[k] = pose2.compose(truth[k - 1], step)
    lms = np.array([[2.0, 3.0], [5.0, -1.0], [7.0, 4.0], [9.0, 1.0], [6.0, 7.0], [3.0, 6.0]])
    odo = pose2.compose(pose2.between(truth[:-1], truth[1:]), np.array([0.02, -0.01, 0.003]))
    i, j, z = [], [], []
    for k in range(n):
        q = pose2.inverse_transform_points(truth[k], lms)
        for m in np.flatnonzero(np.hypot(q[:, 0], q[:, 1]) < 6.0):
            i.append(k)
            j.append(100 + m)
            z.append(q[m] + 0.01 * np.array([(-1) ** k, (-1) ** m]))
    dead = [truth[0]]
    for d in odo:
        dead.append(pose2.compose(dead[-1], d))
    e = len(i)
    graph = GraphData(
        dim=2,
        pose_ids=np.arange(n),
        poses=np.array(dead),
        landmark_ids=np.arange(100, 106),
        landmarks=lms + 0.3,
        edges=(
            EdgeSet(
                "se2",
                np.arange(n - 1),
                np.arange(1, n),
                odo,
                np.broadcast_to(np.diag([100.0, 100.0, 400.0]), (n - 1, 3, 3)).copy(),
                np.zeros(n - 1, dtype=np.int64),
            ),
            EdgeSet(
                "se2_xy",
                np.array(i),
                np.array(j),
                np.array(z),
                np.broadcast_to(np.eye(2) * 25.0, (e, 2, 2)).copy(),
                np.zeros(e, dtype=np.int64),
            ),
        ),
    )
    path = tmp_path / "landmarks.g2o"
    write_graph(graph, path)
    return path


def test_window_on_a_landmark_graph(tmp_path: Path) -> None:
    """A window holding the whole run gives batch's χ²; a window of 3 writes the landmark
    files, counts its re-entries and keeps every step's system small."""
    from slamkit.optim import OptimizerConfig, StoppingConfig, optimize

    src = _landmark_file(tmp_path)
    full, short = tmp_path / "full", tmp_path / "short"
    for out, w in ((full, "12"), (short, "3")):
        res = runner.invoke(app, ["optimize", str(src), "--window", w, "--out", str(out)])
        assert res.exit_code == 0, res.output
    assert sorted(os.listdir(short)) == [
        "config.json", "graph.png", "landmarks.csv", "metrics.json", "online.csv", "optimized.g2o",
    ]  # fmt: skip
    tight = OptimizerConfig(
        solver="gn", initialization="vertices",
        stopping=StoppingConfig(relative_tolerance=0.0, absolute_tolerance=0.0, max_iterations=50),
    )  # fmt: skip
    batch = optimize(read_graph(src), tight)
    m_full = json.loads((full / "metrics.json").read_text())
    m_short = json.loads((short / "metrics.json").read_text())
    assert m_full["chi2_final"] == pytest.approx(batch.cost, rel=1e-9)
    assert m_full["reentries"] == 0 and m_full["landmarks"] == 6
    assert m_short["chi2_final"] > m_full["chi2_final"]
    assert m_short["max_unknowns"] <= 3 * 4 + 2 * 6
    graph = read_graph(full / "optimized.g2o")
    np.testing.assert_allclose(graph.poses, batch.poses, atol=1e-8)
    np.testing.assert_allclose(graph.landmarks, batch.landmarks, atol=1e-8)
