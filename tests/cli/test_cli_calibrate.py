"""``slamkit calibrate``: the wheels' systematic errors, the laser's mounting and the
odometry noise from a data set itself, written as calibration.json and fed back through
run_config.json.

On a generated building (its odometry under the typical error model, glitches included, the
drawn systematic errors recorded in its metadata): the recovered errors against the drawn
ones. On the raw Freiburg 079 log (real data, skipped without it): the files and the values
the docs report. A data set without wheel odometry is one line and exit code 1.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.datasets import load_dataset

runner = CliRunner()


def test_calibrate_a_generated_building(tmp_path: Path) -> None:
    out = tmp_path / "cal"
    res = runner.invoke(app, ["calibrate", "--data", "building", "--seed", "0", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "wheel-radius error [%]" in res.output and "loader takes no noise options" in res.output
    cal = json.loads((out / "calibration.json").read_text())
    injected = load_dataset("building", seed=0).metadata["odometry_errors"]
    fit = cal["systematic"]
    for key in ("wheel_radius_error", "wheel_base_error"):
        assert abs(fit[key] - injected[key]) < max(3 * fit[f"{key}_std"], 0.003), key
    # The laser sits at the robot's centre in the generated buildings.
    assert abs(fit["values"]["mount_x"]) < 0.02 and abs(fit["values"]["mount_y"]) < 0.02
    assert json.loads((out / "run_config.json").read_text())["dataset"]["name"] == "building"


def test_calibrate_refuses_a_run_without_wheel_odometry(tmp_path: Path) -> None:
    res = runner.invoke(app, ["calibrate", "--data", "rooms-laser", "--out", str(tmp_path / "x")])
    assert res.exit_code == 1
    assert "no wheel odometry" in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "x").exists()


def test_calibrate_the_raw_fr079_log(tmp_path: Path, data_root: Path) -> None:
    out = tmp_path / "fr079"
    res = runner.invoke(
        app, ["calibrate", "--data", "fr079-raw", "--data-root", str(data_root), "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    cal = json.loads((out / "calibration.json").read_text())
    fit = cal["systematic"]
    assert cal["pairs"] > 900
    assert abs(fit["wheel_radius_error"]) < 0.01  # measured -0.12 % ± 0.23 %
    assert fit["values"]["mount_x"] == pytest.approx(-0.003, abs=0.01)  # measured -0.34 cm
    step = cal["noise"]["per_step"]["values"]
    assert 0.005 < step["sigma_trans"] < 0.03  # measured 1.39 cm
    config = json.loads((out / "run_config.json").read_text())
    assert config["dataset"]["odometry_sigma_trans"] == step["sigma_trans"]
    assert config["dataset"]["name"] == "fr079-raw"
