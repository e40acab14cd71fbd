"""A relative path not found here is looked up under the data folder, for ``--data`` and the
relations file as for ``optimize``: a command line never needs ``"$SLAMKIT_DATA/…"``, which
is ``/…`` when the variable is unset and the default folder is used."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from slamkit.app.runconfig import RunConfig, resolve_data
from slamkit.cli.main import app
from slamkit.datasets.paths import find_data_file

runner = CliRunner()


def test_find_data_file_here_first_then_under_the_data_folder(tmp_path, monkeypatch):
    data, work = tmp_path / "data", tmp_path / "work"
    (data / "laser").mkdir(parents=True)
    (data / "laser" / "a.log").write_text("x")
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setenv("SLAMKIT_DATA", str(data))
    assert find_data_file("laser/a.log") == data / "laser" / "a.log"
    assert find_data_file("laser/b.log") is None
    (work / "laser").mkdir()
    (work / "laser" / "a.log").write_text("here")
    assert find_data_file("laser/a.log").read_text() == "here"  # here wins
    assert resolve_data("five-features", RunConfig()) == "five-features"  # names stay names
    assert resolve_data("laser/b.log", RunConfig()) == "laser/b.log"  # not found: as given


def test_data_and_relations_paths_under_the_data_folder(tmp_path, monkeypatch, carmen_log):
    data, work = tmp_path / "data", tmp_path / "work"
    (data / "laser").mkdir(parents=True)
    log = carmen_log("corridor.log", scans=8)
    log.rename(data / "laser" / "corridor.log")
    # 1 s apart the robot drove 0.1 m along x (the log's odometry)
    (data / "laser" / "corridor.relations").write_text("1 2 0.1 0 0 0 0 0\n3 5 0.2 0 0 0 0 0\n")
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setenv("SLAMKIT_DATA", str(data))
    res = runner.invoke(app, ["run", "dead-reckoning", "--data", "laser/corridor.log",
                              "--no-plots", "--out", "dr"])  # fmt: skip
    assert res.exit_code == 0, res.output
    config = json.loads((work / "dr" / "config.json").read_text())
    assert config["dataset"]["path"] == str(data / "laser" / "corridor.log")
    res = runner.invoke(app, ["eval", "relations", "dr/trajectory.tum",
                              "laser/corridor.relations", "--json", "rel.json"])  # fmt: skip
    assert res.exit_code == 0, res.output
    scores = json.loads((work / "rel.json").read_text())["relations"]
    assert scores["count"] == 2 and scores["translation_max"] < 0.02  # both found and scored
