"""``slamkit optimize FILE --objective sesync --certify``: the certificate in the summary and in
``metrics.json``; a local minimum reached from the file's vertices is not certified; the
options and graphs the certificate does not cover are one-line errors that write nothing."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.geometry import pose2
from slamkit.io.posegraph import read_graph, write_graph
from slamkit.optim import EdgeSet, GraphData, sesync_objective

runner = CliRunner()


def _ring_file(tmp_path: Path, *, winding: bool) -> tuple[Path, GraphData]:
    """16 poses on a 10 m circle, odometry and two chords across, noise σ = (0.05 m, 0.05 m,
    0.01 rad); vertices: the truth, or the truth with one extra turn of heading (pose k
    turned by 2πk/16)."""
    rng = np.random.default_rng(7)
    a = 2 * np.pi * np.arange(16) / 16
    truth = np.column_stack([10 * np.cos(a), 10 * np.sin(a), a + np.pi / 2])
    i = np.r_[np.arange(16), 0, 4]
    j = np.r_[(np.arange(16) + 1) % 16, 8, 12]
    sigma = np.array([0.05, 0.05, 0.01])
    z = pose2.between(truth[i], truth[j]) + rng.normal(size=(18, 3)) * sigma
    info = np.broadcast_to(np.diag(1.0 / sigma**2), (18, 3, 3)).copy()
    poses = truth + np.c_[np.zeros((16, 2)), a if winding else np.zeros(16)]
    poses[:, 2] = np.arctan2(np.sin(poses[:, 2]), np.cos(poses[:, 2]))
    edges = EdgeSet("se2", i, j, z, info, np.zeros(18, dtype=np.int64))
    graph = GraphData(dim=2, pose_ids=np.arange(16), poses=poses, edges=(edges,))
    return write_graph(graph, tmp_path / "ring.g2o", family="g2o"), graph


def _run(src: Path, out: Path, *args: str) -> dict:
    res = runner.invoke(
        app, ["optimize", str(src), "--out", str(out), "--objective", "sesync", "--certify",
              "--no-plots", *args],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    metrics = json.loads((out / "metrics.json").read_text())
    verdict = "globally optimal" if metrics["certificate"]["certified"] else "not certified"
    assert verdict in res.output
    assert f"{metrics['certificate']['lower_bound']:.6g}" in res.output
    return metrics


def test_certify_reports_the_optimum_certified(tmp_path: Path) -> None:
    src, _ = _ring_file(tmp_path, winding=False)
    cert = _run(src, tmp_path / "out")["certificate"]
    assert cert["certified"] is True
    assert abs(cert["lambda_min"]) < 1e-9 * cert["q_norm"]
    assert cert["tolerance"] == pytest.approx(1e-6 * cert["q_norm"])
    assert cert["lower_bound"] <= cert["objective"] < cert["lower_bound"] + 1e-4 * cert["objective"]
    assert cert["poses"] == 16
    written = json.loads((tmp_path / "out" / "config.json").read_text())
    assert written["certify"] is True


def test_certify_rejects_the_winding_local_minimum(tmp_path: Path) -> None:
    """``--init file`` from the winding vertices: LM stops at F ≈ 1.3e5, not certified, and
    the bound is still below the optimum's F."""
    src, graph = _ring_file(tmp_path, winding=True)
    best = _run(src, tmp_path / "best")["certificate"]  # auto start: chordal wins
    cert = _run(src, tmp_path / "bad", "--init", "file")["certificate"]
    assert best["certified"] and not cert["certified"]
    assert cert["objective"] > 1e3 * best["objective"]  # 1.3e5 against 21
    assert cert["lambda_min"] < -0.1 * cert["q_norm"]
    assert cert["lower_bound"] <= best["objective"]
    optimum = read_graph(tmp_path / "best" / "optimized.g2o").poses
    assert best["objective"] == pytest.approx(sesync_objective(graph, optimum), rel=1e-6)


def test_certify_needs_the_sesync_objective(tmp_path: Path) -> None:
    src, _ = _ring_file(tmp_path, winding=False)
    res = runner.invoke(app, ["optimize", str(src), "--out", str(tmp_path / "o"), "--certify"])
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert "add --objective sesync" in lines[0]
    assert not (tmp_path / "o").exists()


def test_certify_refuses_a_landmark_graph(tmp_path: Path) -> None:
    """SE-Sync's problem has no landmarks: refused before any work, nothing written."""
    _, ring = _ring_file(tmp_path, winding=False)
    xy = EdgeSet("se2_xy", np.array([0]), np.array([100]), np.array([[1.0, 0.5]]),
                 np.eye(2)[None] * 100.0, np.zeros(1, dtype=np.int64))  # fmt: skip
    graph = GraphData(dim=2, pose_ids=ring.pose_ids, poses=ring.poses,
                      landmark_ids=np.array([100]), landmarks=np.array([[11.0, 0.5]]),
                      edges=(*ring.edges, xy))  # fmt: skip
    src = write_graph(graph, tmp_path / "landmarks.g2o", family="g2o")
    res = runner.invoke(
        app, ["optimize", str(src), "--out", str(tmp_path / "o"), "--objective", "sesync",
              "--certify"],
    )  # fmt: skip
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert "relative-pose (se2) edges only" in lines[0] and "se2_xy" in lines[0]
    assert not (tmp_path / "o").exists()


@pytest.mark.realdata
def test_certify_a_3d_graph(data_root: Path, tmp_path: Path) -> None:
    """tinyGrid3D (9 poses): certified, F = 18.5194 (SE-Sync's objective from chordal)."""
    src = data_root / "posegraph3d" / "tinyGrid3D.g2o"
    if not src.exists():
        pytest.skip(f"{src} not found")
    cert = _run(src, tmp_path / "o")["certificate"]
    assert cert["certified"] and cert["poses"] == 9
    assert cert["objective"] == pytest.approx(18.5194, abs=1e-4)
    assert cert["lower_bound"] <= cert["objective"] < cert["lower_bound"] + 1e-4


def test_staircase_writes_the_certified_optimum_from_the_winding_minimum(tmp_path: Path) -> None:
    """``--init file --staircase``: LM's winding minimum (F ≈ 1.3e5) is refused, the
    staircase climbs to a certifying rank and the written graph holds its poses, whose F is
    the chordal run's certified optimum."""
    src, graph = _ring_file(tmp_path, winding=True)
    best = _run(src, tmp_path / "best")["certificate"]
    res = runner.invoke(
        app, ["optimize", str(src), "--out", str(tmp_path / "o"), "--objective", "sesync",
              "--certify", "--staircase", "--init", "file", "--no-plots"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    metrics = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert not metrics["certificate"]["certified"]  # LM's answer, as before
    stair = metrics["staircase"]
    assert stair["certified"] and stair["certificate"]["certified"]
    assert stair["ranks_climbed"] >= 1 and stair["final_rank"] == 2 + stair["ranks_climbed"]
    assert stair["objective"] == pytest.approx(best["objective"], rel=1e-8)
    assert stair["relaxation_objective"] == pytest.approx(best["objective"], rel=1e-8)
    written = read_graph(tmp_path / "o" / "optimized.g2o").poses
    assert sesync_objective(graph, written) == pytest.approx(best["objective"], rel=1e-6)
    assert "staircase ranks" in res.output and "climbed" in res.output
    assert f"{stair['objective']:.6g}" in res.output
    assert "Riemannian staircase" in res.output  # the note on what the file holds
    assert json.loads((tmp_path / "o" / "config.json").read_text())["staircase"] is True


def test_staircase_is_skipped_when_already_certified_and_needs_certify(tmp_path: Path) -> None:
    src, _ = _ring_file(tmp_path, winding=False)
    metrics = _run(src, tmp_path / "o", "--staircase")
    assert metrics["certificate"]["certified"] and "staircase" not in metrics
    res = runner.invoke(
        app, ["optimize", str(src), "--out", str(tmp_path / "x"), "--objective", "sesync",
              "--staircase"],
    )  # fmt: skip
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert "add --certify" in lines[0]
    assert not (tmp_path / "x").exists()


def test_staircase_not_certified_keeps_the_optimisers_poses(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With the staircase stopped at rank 2 (below the 4 the winding minimum needs) nothing
    is certified: metrics.json records it with ``written: false`` and the graph file holds
    LM's poses, as a note says."""
    import slamkit.app.optimize as job
    from slamkit.optim import StaircaseConfig, riemannian_staircase

    def rank_two(data: GraphData, poses: np.ndarray) -> object:
        return riemannian_staircase(data, poses, StaircaseConfig(max_rank=2))

    monkeypatch.setattr(job, "riemannian_staircase", rank_two)
    src, graph = _ring_file(tmp_path, winding=True)
    res = runner.invoke(
        app, ["optimize", str(src), "--out", str(tmp_path / "o"), "--objective", "sesync",
              "--certify", "--staircase", "--init", "file", "--no-plots"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    metrics = json.loads((tmp_path / "o" / "metrics.json").read_text())
    stair = metrics["staircase"]
    assert not stair["certified"] and stair["written"] is False
    assert stair["final_rank"] == 2 and stair["ranks_climbed"] == 0
    written = read_graph(tmp_path / "o" / "optimized.g2o").poses
    assert sesync_objective(graph, written) == pytest.approx(
        metrics["sesync_objective_final"], rel=1e-9
    )
    assert "the optimiser's poses are written" in res.output


@pytest.mark.realdata
def test_staircase_on_mit_from_its_vertices(data_root: Path, tmp_path: Path) -> None:
    """MIT.g2o from its vertices: LM stops uncertified at F ≈ 1298 (a local minimum); the
    staircase climbs 2 → 3 → 4 and writes the certified optimum F* = 61.1541 (LM's from the
    chordal start, docs/estimators/optim.md)."""
    src = data_root / "posegraph2d" / "MIT.g2o"
    if not src.exists():
        pytest.skip(f"{src} not found")
    metrics = _run(src, tmp_path / "o", "--staircase", "--init", "file")
    assert not metrics["certificate"]["certified"]
    assert metrics["sesync_objective_final"] > 1000.0
    stair = metrics["staircase"]
    assert stair["certified"] and stair["written"]
    assert [s["rank"] for s in stair["steps"]] == [2, 3, 4]
    assert stair["objective"] == pytest.approx(61.1541, abs=1e-4)
    assert stair["certificate"]["lower_bound"] <= stair["objective"]
    assert stair["certificate"]["gap"] < 1e-3
    graph = read_graph(src)
    written = read_graph(tmp_path / "o" / "optimized.g2o").poses
    assert sesync_objective(graph, written) == pytest.approx(61.1541, abs=1e-3)
