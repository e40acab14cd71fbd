"""The user says which reader, which topics, the mounting and the odometry source: the
``[dataset]`` table of a config file and ``--set dataset.KEY=VALUE`` reach the reader of a
file, for ``slamkit run``, ``slamkit map occupancy`` and ``slamkit config show``, and a run's
``config.json`` re-runs it with the same reader."""

from __future__ import annotations

import json
import tomllib

import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.io import read_tum

runner = CliRunner()


def _ok(*args: str) -> str:
    res = runner.invoke(app, list(args))
    assert res.exit_code == 0, res.output
    return res.output


def _dataset(out):
    return json.loads((out / "config.json").read_text())["dataset"]


def test_the_reader_is_named_by_set_or_by_the_config_file_and_config_json_keeps_it(
    tmp_path, carmen_log
):
    log = carmen_log()  # NEFF lines: read as a corrected log (poses as truth) by content
    by_content, by_set, by_file, again = (tmp_path / n for n in ("c", "s", "f", "a"))
    _ok("run", "dead-reckoning", "--data", str(log), "--out", str(by_content), "--no-plots")
    assert _dataset(by_content)["reader"] == "carmen-corrected"
    assert "ate" in json.loads((by_content / "metrics.json").read_text())
    _ok("run", "dead-reckoning", "--data", str(log), "--set", "dataset.reader=carmen-raw",
        "--out", str(by_set), "--no-plots")  # fmt: skip
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[dataset]\npath = "{log}"\nreader = "carmen-raw"\n')
    _ok("run", "dead-reckoning", "--config", str(cfg), "--out", str(by_file), "--no-plots")
    for out in (by_set, by_file):
        written = _dataset(out)
        assert written["reader"] == "carmen-raw" and written["path"] == str(log.resolve())
        assert "laser" in written  # the raw reader's option (which laser message)
        assert "ate" not in json.loads((out / "metrics.json").read_text())  # a raw log: no truth
        # The raw odometry of the FLASER lines, not poses with drawn noise.
        times, poses = read_tum(out / "trajectory.tum")
        assert poses[-1, 0] == pytest.approx(0.5) and times.size == 6
    # config.json re-runs the run with the reader it named, not the one the content calls for.
    _ok("run", "dead-reckoning", "--config", str(by_set / "config.json"), "--out", str(again),
        "--no-plots")  # fmt: skip
    assert (again / "trajectory.tum").read_bytes() == (by_set / "trajectory.tum").read_bytes()
    res = runner.invoke(app, ["run", "dead-reckoning", "--data", str(log), "--set",
                              "dataset.reader=carmen", "--out", str(tmp_path / "x")])  # fmt: skip
    assert res.exit_code == 1 and "reader: expected one of rosbag, carmen-raw" in res.output


def test_map_occupancy_reads_the_config_files_dataset_path(tmp_path, carmen_log, monkeypatch):
    log = carmen_log()
    cfg = tmp_path / "m.toml"
    cfg.write_text(f'seed = 2\n[dataset]\npath = "{log}"\nlenient = true\n')
    monkeypatch.chdir(tmp_path)
    _ok("map", "occupancy", "--config", str(cfg), "--no-agreement")
    out = tmp_path / "results" / "map-run"  # named by the file, as `slamkit run` names it
    written = _dataset(out)
    assert written["path"] == str(log.resolve()) and written["lenient"] is True
    assert written["reader"] == "carmen-corrected"
    quality = json.loads((out / "quality.json").read_text())
    assert quality["reading"]["used"] == 6
    # Its config.json maps the same file again.
    _ok("map", "occupancy", "--config", str(out / "config.json"), "--no-agreement",
        "--out", str(tmp_path / "again"))  # fmt: skip
    assert (tmp_path / "again" / "map.pgm").read_bytes() == (out / "map.pgm").read_bytes()


def test_bag_options_go_through_set_and_config_show_documents_them(bags, tmp_path):
    S = 1_000_000_000
    scans = [bags.Scan(10 * S + k * S // 10, [4.0] * 5, frame_id="laser") for k in range(8)]
    odometry = [bags.Odom(10 * S + k * S // 10 - S // 20, (0.1 * k, 0.0, 0.0)) for k in range(9)]
    spec = bags.Bag(scans, odometry, scan_topic="/front/scan")
    bag = bags.write(tmp_path / "robot.bag", spec)
    res = runner.invoke(app, ["run", "dead-reckoning", "--data", str(bag), "--out",
                              str(tmp_path / "x")])  # fmt: skip
    assert res.exit_code == 1 and "/front/scan" in res.output  # the default /scan is not there
    out = tmp_path / "o"
    options = ("scan_topic=/front/scan", "mounting=[0.2, 0, 0]", 'odometry_source="topic"',
               "max_duration_s=0.45")  # fmt: skip
    sets = [arg for option in options for arg in ("--set", f"dataset.{option}")]
    _ok("run", "dead-reckoning", "--data", str(bag), "--out", str(out), "--no-plots", *sets)
    written = _dataset(out)
    assert written["scan_topic"] == "/front/scan" and written["mounting"] == [0.2, 0.0, 0.0]
    assert written["odometry_source"] == "topic" and written["reader"] == "rosbag"
    assert json.loads((out / "metrics.json").read_text())["reading"]["used"] == 5  # 0.45 s
    text = _ok("config", "show", "dead-reckoning", "--data", str(bag))
    table = tomllib.loads(text)["dataset"]
    assert table["path"] == str(bag.resolve()) and table["odometry_source"] == "auto"
    assert "# Topic of the ``sensor_msgs/msg/LaserScan`` messages." in text
    assert "# The laser's pose ``(x, y, yaw)`` on the robot [m, m, rad]" in text
    assert '# reader = "rosbag"' in text
