"""Default output folders never collide: a command run twice with its defaults writes a
second, numbered folder, and a re-run from a run's ``config.json`` never writes into the
folder it read from."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.io import fresh_folder

runner = CliRunner()


def test_fresh_folder_numbers_taken_folders_and_avoids_one(tmp_path):
    base = tmp_path / "results" / "run"
    assert fresh_folder(base) == base  # missing
    base.mkdir(parents=True)
    assert fresh_folder(base) == base  # empty
    (base / "metrics.json").write_text("{}")
    assert fresh_folder(base) == tmp_path / "results" / "run-2"
    (tmp_path / "results" / "run-2").mkdir()
    (tmp_path / "results" / "run-2" / "x").write_text("")
    assert fresh_folder(base) == tmp_path / "results" / "run-3"
    empty = tmp_path / "results" / "run-3"
    empty.mkdir()
    assert fresh_folder(base, avoid=empty) == tmp_path / "results" / "run-4"


def test_run_twice_and_rerun_from_config_json_with_default_folders(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = ["run", "dead-reckoning", "--data", "five-features", "--seed", "3", "--no-plots"]
    first = tmp_path / "results" / "dead-reckoning-five-features"
    for name in (first.name, f"{first.name}-2"):
        res = runner.invoke(app, argv)
        assert res.exit_code == 0, res.output
        assert (tmp_path / "results" / name / "trajectory.tum").is_file()
    config = first / "config.json"
    before = {p.name: p.read_bytes() for p in first.iterdir()}
    res = runner.invoke(app, ["run", "dead-reckoning", "--config", str(config), "--no-plots"])
    assert res.exit_code == 0, res.output
    rerun = tmp_path / "results" / f"{first.name}-3"
    assert (rerun / "trajectory.tum").read_bytes() == before["trajectory.tum"]
    assert {p.name: p.read_bytes() for p in first.iterdir()} == before  # untouched


@pytest.mark.parametrize("out", ["same", "same-relative"])
def test_a_rerun_into_its_config_folder_is_refused(tmp_path, monkeypatch, out):
    monkeypatch.chdir(tmp_path)
    folder = tmp_path / "r"
    res = runner.invoke(app, ["run", "dead-reckoning", "--out", str(folder), "--no-plots"])
    assert res.exit_code == 0, res.output
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    target = str(folder) if out == "same" else "r/../r"
    res = runner.invoke(app, ["run", "dead-reckoning", "--config", str(folder / "config.json"),
                              "--out", target, "--overwrite", "--no-plots"])  # fmt: skip
    assert res.exit_code == 1
    assert "was read from" in res.output and "Traceback" not in res.output
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
