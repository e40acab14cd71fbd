"""The CLI on a simulated scenario: files, metrics, error messages, exit codes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.datasets import load_dataset
from slamkit.io import read_tum

runner = CliRunner()


def test_run_dead_reckoning_writes_trajectory_metrics_config_and_plots(tmp_path):
    out = tmp_path / "dr"
    res = runner.invoke(
        app, ["run", "dead-reckoning", "--data", "five-features", "--seed", "3", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    files = sorted(p.name for p in out.iterdir())
    assert files == [
        "config.json",
        "errors.png",
        "groundtruth.tum",
        "metrics.json",
        "nees.png",
        "report.html",
        "trajectory.png",
        "trajectory.tum",
    ]
    for png in ("trajectory.png", "errors.png", "nees.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    metrics = json.loads((out / "metrics.json").read_text())
    config = json.loads((out / "config.json").read_text())
    assert config["seed"] == 3 and config["estimator"]["name"] == "dead-reckoning"
    assert config["dataset"]["name"] == "five-features" and config["dataset"]["dt"] == 0.1
    # The written trajectory is the dead-reckoned one: its final error matches the metric.
    t, poses = read_tum(out / "trajectory.tum")
    truth = load_dataset("five-features", seed=3).truth
    np.testing.assert_allclose(t, truth.times, atol=1e-9)
    err = np.hypot(*(poses[-1, :2] - truth.poses[-1, :2]))
    assert err == pytest.approx(metrics["final_position_error"], abs=1e-6)
    assert metrics["ate_unaligned"]["rmse"] > metrics["ate"]["rmse"] > 0
    # The summary table shows the metric with its unit.
    assert "ATE RMSE, unaligned [m]" in res.output
    assert f"{metrics['ate_unaligned']['rmse']:.3f}" in res.output


def test_config_file_sets_estimator_and_dataset(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text("seed = 5\n[estimator]\nmotion_cov_scale = 4.0\n[dataset]\nsigma_v = 0.2\n")
    out = tmp_path / "o"
    res = runner.invoke(
        app, ["run", "dead-reckoning", "--config", str(cfg), "--out", str(out), "--no-plots"]
    )
    assert res.exit_code == 0, res.output
    config = json.loads((out / "config.json").read_text())
    assert config["seed"] == 5
    assert config["estimator"]["motion_cov_scale"] == 4.0
    assert config["dataset"]["sigma_v"] == 0.2
    assert not list(out.glob("*.png"))


@pytest.mark.parametrize(
    "args,message",
    [
        (["run", "kalman-magic"], "unknown estimator 'kalman-magic'"),
        (["run", "dead-reckoning", "--data", "atlantis"], "unknown dataset 'atlantis'"),
    ],
)
def test_known_errors_are_one_line_with_exit_code_1(tmp_path, args, message):
    res = runner.invoke(app, [*args, "--out", str(tmp_path / "x")])
    assert res.exit_code == 1
    assert message in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "x").exists()


def test_bad_config_leaves_no_output_folder(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[estimator]\nnoise_scale = -1.0\n")
    res = runner.invoke(
        app, ["run", "dead-reckoning", "--config", str(cfg), "--out", str(tmp_path / "x")]
    )
    assert res.exit_code == 1 and "motion_cov_scale" in res.output
    assert not (tmp_path / "x").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["c.toml"]


def test_data_list_and_estimators():
    res = runner.invoke(app, ["data", "list"])
    assert res.exit_code == 0
    for name in ("five-features", "landmark-loop", "rooms-laser"):
        assert name in res.output
    res = runner.invoke(app, ["estimators"])
    assert res.exit_code == 0 and "dead-reckoning" in res.output


def test_demo_writes_results(tmp_path):
    res = runner.invoke(app, ["demo", "--out", str(tmp_path / "demo")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "demo" / "metrics.json").exists()
    # the demo is SLAM: a map, a pose graph and a trajectory error well below the drift
    import json

    for name in ("map.png", "graph.g2o", "trajectory.tum", "trajectory.png"):
        assert (tmp_path / "demo" / name).exists(), name
    metrics = json.loads((tmp_path / "demo" / "metrics.json").read_text())
    assert metrics["estimator"] == "graph-slam" and metrics["ate"]["rmse"] < 0.2
    assert str(tmp_path / "demo") in res.output.replace("\n", "")


@pytest.mark.parametrize(
    "toml,message",
    [
        ("[dataset]\nsigma_range = nan\n", "expected a finite number"),
        ("[dataset]\nsigma_range = 0.0\n", "sigma_range"),
        ("[dataset]\nsensor = 3\n", "expected one of"),
        ("[estimatr]\n", "unknown section"),
    ],
)
def test_bad_values_in_a_config_file_are_one_line_errors(tmp_path, toml, message):
    cfg = tmp_path / "c.toml"
    cfg.write_text(toml)
    res = runner.invoke(
        app, ["run", "dead-reckoning", "--config", str(cfg), "--out", str(tmp_path / "x")]
    )
    assert res.exit_code == 1, res.output
    assert message in res.output and "Traceback" not in res.output
    assert not (tmp_path / "x").exists()


def test_help_shows_config_table_names_and_the_optimize_command():
    """Rich markup would read "[estimator]" and "[dataset]" as tags and drop them."""
    res = runner.invoke(app, ["run", "--help"])
    assert res.exit_code == 0
    assert "[estimator]" in res.output and "[dataset]" in res.output
    res = runner.invoke(app, ["--help"])
    assert res.exit_code == 0 and "optimize" in res.output


def test_animate_writes_a_gif_of_the_estimate_over_time(tmp_path):
    """`--animate` on EKF-SLAM: a GIF with one image per runner frame (about
    ANIMATION_FRAMES, evenly spaced in time, the last at the end of the run); the last
    frame's map is the final map; the table shows the SLAM scores."""
    from PIL import Image

    from slamkit.app.jobs import ANIMATION_FRAMES
    from slamkit.pipeline import run

    out = tmp_path / "slam"
    res = runner.invoke(
        app, ["run", "ekf-slam", "--data", "five-features", "--out", str(out), "--animate"]
    )
    assert res.exit_code == 0, res.output
    with Image.open(out / "animation.gif") as gif:
        n_images = gif.n_frames
    assert ANIMATION_FRAMES <= n_images <= ANIMATION_FRAMES + 2
    (mapped,) = [s for s in res.output.splitlines() if "landmarks matched to a true one" in s]
    (missed,) = [s for s in res.output.splitlines() if "true landmarks not mapped" in s]
    assert mapped.split()[-2] == "5" and missed.split()[-2] == "0"
    result = run("ekf-slam", load_dataset("five-features", seed=0), frames=10)
    assert 10 <= len(result.frames) <= 12
    t = np.array([f.t for f in result.frames])
    assert np.all(np.diff(t) > 0) and t[-1] == result.times[-1]
    last, final = result.frames[-1].landmarks, result.output.landmarks
    assert last is not None and final is not None
    np.testing.assert_array_equal(last.landmarks.positions, final.landmarks.positions)
    np.testing.assert_array_equal(result.frames[-1].pose, result.poses[-1])


def test_a_run_job_lays_the_matching_preset_under_the_config(tmp_path, monkeypatch):
    """``slamkit run`` resolves the preset measured for the estimator on the data set, lays
    the config file's mapping over it, and config.json records the preset and every
    setting used."""
    from slamkit.app import jobs, presets
    from slamkit.errors import InputError

    tuned = presets.Preset("test-preset", ("fastslam1",), ("five-features",), {"hit_weight": 4})
    monkeypatch.setitem(presets.PRESETS, "test-preset", tuned)
    request = jobs.RunRequest("fastslam1", "five-features", tmp_path / "out",
                              estimator_config={"n_particles": 20}, plots=False)  # fmt: skip
    report = jobs.run_job(request)
    written = json.loads((report.out_dir / "config.json").read_text())
    cfg = written["estimator"]
    assert cfg["hit_weight"] == 4 and cfg["n_particles"] == 20
    assert written["preset"] == "test-preset"
    assert report.result.config == {k: v for k, v in cfg.items() if k != "name"}
    assert report.preset == "test-preset" and report.preset_settings == {"hit_weight": 4}
    # no preset: the estimator's own defaults
    plain = jobs.run_job(
        jobs.RunRequest("fastslam1", "five-features", tmp_path / "plain", plots=False, preset=None)
    )
    assert plain.result.config["hit_weight"] == 1 and plain.preset is None
    with pytest.raises(InputError, match="test-preset"):
        jobs.run_job(
            jobs.RunRequest("ekf-slam", "five-features", tmp_path / "x", preset="test-preset")
        )


def test_run_prints_the_consistency_warning_and_writes_it_to_metrics(tmp_path):
    # σ = 1e-6 readings: EKF localization keeps going, over-confident by ~10⁶ (the monitor)
    out = tmp_path / "tiny-noise"
    args = ["run", "ekf-localization", "--no-plots", "--out", str(out)]
    args += ["--set", "dataset.sigma_range=1e-6", "--set", "dataset.sigma_bearing_deg=1e-6"]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    assert "warning: NEES inconsistent (over-confident)" in " ".join(res.output.split())
    warnings = json.loads((out / "metrics.json").read_text())["warnings"]
    nees = [w for w in warnings if w["statistic"] == "nees"]
    assert len(nees) == 1 and nees[0]["value"] > 1e5 * nees[0]["band"][1]
    assert nees[0]["first"] == 0 and nees[0]["last"] == 49
