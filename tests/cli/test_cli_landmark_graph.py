"""``slamkit landmark-graph``: a landmark data set solved as a factor graph, its GPS fused.

On the simulated loop (no GPS track): the graph's landmarks against the true map. On the
first 200 s of Victoria Park (real data, skipped without it): the fused graph's held-out GPS
error, its lever arm, and the files written.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.io.landmarks import read_landmarks_csv
from slamkit.io.tum import read_tum
from slamkit.sim.scenarios import build_landmark_loop

runner = CliRunner()


def test_landmark_graph_on_the_simulated_loop(tmp_path: Path) -> None:
    """Without GPS (the scenario has none, so ``--gps`` would be refused): the map of the
    solved graph (in the frame of the prior, which the true start misses by 6 cm) lies within
    0.3 m RMS of the true landmarks (measured 0.21 m, 0.16 m after an SE(2) alignment; the
    dead-reckoned first sightings: 8.9 m), and every landmark read is in it."""
    out = tmp_path / "run"
    res = runner.invoke(
        app, ["landmark-graph", "--data", "landmark-loop", "--no-gps", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert "poses / landmarks" in res.output
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["unfused"]["converged"]
    lm, _ = read_landmarks_csv(out / "landmarks.csv")
    ds = build_landmark_loop({}, seed=0)
    assert ds.truth.landmarks is not None
    true = dict(zip(ds.truth.landmarks.ids.tolist(), ds.truth.landmarks.positions, strict=True))
    err = np.array([lm.positions[k] - true[int(i)] for k, i in enumerate(lm.ids)])
    assert ds.truth.reading_ids is not None
    seen = np.unique(np.concatenate(ds.truth.reading_ids))
    assert metrics["unfused"]["landmarks"] == lm.ids.shape[0] == seen.shape[0]
    rmse = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    assert rmse < 0.3
    _, poses = read_tum(out / "trajectory.tum")
    assert poses.shape == (metrics["unfused"]["poses"], 3)
    refused = runner.invoke(app, ["landmark-graph", "--data", "landmark-loop", "--out", str(out)])
    assert refused.exit_code == 1 and "no GPS track" in refused.output
    typo = runner.invoke(
        app, ["landmark-graph", "--data", "landmark-loop", "--weighting", "tukey", "--out",
              str(tmp_path / "typo")],
    )  # fmt: skip
    assert typo.exit_code == 1 and "weighting: expected one of" in typo.output
    assert not (tmp_path / "typo").exists()


@pytest.mark.realdata
def test_landmark_graph_fuses_victoria_park_gps(tmp_path: Path, data_root: Path) -> None:
    """The first 200 s of Victoria Park with every tenth fix held out: the fused graph misses
    the held-out fixes by an RMSE under 1.6 m without any alignment (measured 1.23 m; the
    graph without GPS, aligned, scored at its rear axle: 4.49 m), the lever arm lies on the
    truck's cab (x 3-5.5 m ahead of the rear axle, |y| < 1 m; measured (4.26, 0.34) m on
    these 200 s, (3.98, 0.41) m on the whole run), and the files are written."""
    out = tmp_path / "vp"
    res = runner.invoke(
        app,
        ["landmark-graph", "--data", "victoria-park", "--max-duration", "200", "--out",
         str(out), "--data-root", str(data_root)],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    m = json.loads((out / "metrics.json").read_text())
    fused = m["fused"]
    assert fused["converged"] and fused["landmarks"] == m["unfused"]["landmarks"]
    assert fused["holdout"]["direct_rmse"] < 1.6
    assert fused["holdout"]["direct_rmse"] < m["unfused"]["holdout"]["rmse"]
    assert 3.0 < fused["lever_arm"][0] < 5.5 and abs(fused["lever_arm"][1]) < 1.0
    for name in ("trajectory.tum", "trajectory_unfused.tum", "landmarks.csv", "graph.png"):
        assert (out / name).stat().st_size > 0


def test_landmark_graph_window_on_the_simulated_loop(tmp_path: Path) -> None:
    """``--window 5``: the graph without GPS smoothed beside batch. Measured on seed 0: the
    online estimates 1.78 m RMS (3.97 m max) from batch, which closes the loop the window
    cannot; two landmark re-entries (landmarks of the start seen again at the end); the
    bound leaves ~40 % margin."""
    out = tmp_path / "win"
    res = runner.invoke(
        app, ["landmark-graph", "--data", "landmark-loop", "--window", "5", "--no-plots",
              "--out", str(out)],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "fixed-lag, window 5" in res.output
    m = json.loads((out / "metrics.json").read_text())
    sm, ba = m["smoothed"], m["batch"]
    assert m["window"] == 5 and sm["poses"] == ba["poses"] and sm["gps"] is None
    assert sm["reentries"] == 2 and sm["converged"]
    assert m["against_batch"]["rmse"] < 2.5
    _, smoothed = read_tum(out / "trajectory.tum")
    _, batch = read_tum(out / "trajectory_batch.tum")
    d = np.hypot(*(smoothed[:, :2] - batch[:, :2]).T)
    assert float(np.sqrt(np.mean(d**2))) == pytest.approx(m["against_batch"]["rmse"], rel=1e-6)


@pytest.mark.realdata
def test_landmark_graph_hierarchical_on_victoria_park(tmp_path: Path, data_root: Path) -> None:
    """``--hierarchical 100`` on the first 200 s of Victoria Park: local maps of 100 poses
    joined by their base frames; the held-out fixes are missed by a direct RMSE under 1.6 m
    (measured 0.87 m; the flat graph 1.23 m), the lever arm is on the cab (measured
    (3.63, 0.72) m), the hierarchy's sizes are reported, and the unfused solution is written
    beside it."""
    out = tmp_path / "vp-h"
    res = runner.invoke(
        app,
        ["landmark-graph", "--data", "victoria-park", "--max-duration", "200",
         "--hierarchical", "100", "--no-plots", "--out", str(out), "--data-root",
         str(data_root)],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "submaps / largest system" in res.output
    m = json.loads((out / "metrics.json").read_text())
    h, fused = m["hierarchy"], m["fused"]
    assert h["submap_poses"] == 100 and h["submaps"] == -(-(fused["poses"] - 1) // 100)
    assert h["top_variables"] == 3 * (h["submaps"] + 1) + 2
    assert fused["converged"] and fused["landmarks"] == m["unfused"]["landmarks"]
    assert fused["holdout"]["direct_rmse"] < 1.6
    assert 3.0 < fused["lever_arm"][0] < 5.5 and abs(fused["lever_arm"][1]) < 1.0
    for name in ("trajectory.tum", "trajectory_unfused.tum", "landmarks.csv"):
        assert (out / name).stat().st_size > 0


def test_landmark_graph_hierarchical_needs_batch_gps(tmp_path: Path) -> None:
    out = tmp_path / "h"
    res = runner.invoke(
        app, ["landmark-graph", "--data", "landmark-loop", "--no-gps", "--hierarchical", "50",
              "--out", str(out)],
    )  # fmt: skip
    assert res.exit_code == 1 and "hierarchical: fuses the GPS in batch" in res.output
    assert not out.exists()
