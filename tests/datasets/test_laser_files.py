"""Laser logs from a path (``load_file``, ``load_data``, ``slamkit run --data PATH``) and the
laser's mounting in :class:`LaserSpec`."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.datasets import LaserScan, LaserSpec, Odometry
from slamkit.datasets.files import data_label, file_format, load_data, load_file
from slamkit.errors import (
    DataNotFoundError,
    DatasetFormatError,
    InputError,
    NonFiniteError,
    UnknownNameError,
)
from slamkit.io import read_tum

runner = CliRunner()
S = 1_000_000_000


def _bag(bags: SimpleNamespace, path: Path, kind: str = "ros1") -> Path:
    scans = [bags.Scan(S + k * S // 10, [1.0, 2.0, 3.0]) for k in range(5)]
    odometry = [bags.Odom(S + k * S // 10, (0.1 * k, 0.0, 0.05 * k)) for k in range(5)]
    return bags.write(path, bags.Bag(scans, odometry), kind)


CLF = "\n".join(
    f"FLASER 180 {' '.join(['2.0'] * 180)} {0.1 * k!r} 0.0 0.0 {0.1 * k!r} 0.0 0.0 "
    f"{10.0 + k!r} host {10.0 + k!r}"
    for k in range(3)
)


# ------------------------------------------------------------------------ file kinds
@pytest.mark.parametrize(
    ("name", "kind"),
    [
        ("a.bag", "rosbag"),
        ("a.db3", "rosbag"),
        ("a.mcap", "rosbag"),
        ("a.clf", "carmen-raw"),
        ("a.log", "carmen-raw"),
        ("a.log.gz", "carmen-raw"),
        ("a.gz", "carmen-raw"),
    ],
)
def test_file_format_by_suffix(tmp_path, name, kind):
    (tmp_path / name).write_bytes(b"")
    assert file_format(tmp_path / name) == kind


def test_folders_unknown_suffixes_and_missing_files(tmp_path):
    (tmp_path / "bag2").mkdir()
    (tmp_path / "bag2" / "metadata.yaml").write_text("")
    assert file_format(tmp_path / "bag2") == "rosbag"
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetFormatError, match=r"without metadata.yaml .*supported: ROS 1 .bag"):
        file_format(tmp_path / "empty")
    (tmp_path / "scan.txt").write_text("1 2 3\n")
    with pytest.raises(DatasetFormatError, match=r"unknown kind of file '.txt' \(supported: ROS"):
        load_file(tmp_path / "scan.txt")
    with pytest.raises(DataNotFoundError, match=r"nope.bag: not found \(supported: ROS 1 .bag"):
        load_file(tmp_path / "nope.bag")


def test_load_file_reads_bags_and_carmen_logs_and_records_the_path(bags, tmp_path):
    ros1 = load_file(_bag(bags, tmp_path / "r.bag"))
    ros2 = load_file(_bag(bags, tmp_path / "r2", "ros2"))
    for ds in (ros1, ros2):
        assert [e.t for e in ds.events if isinstance(e, LaserScan)] == [1.0, 1.1, 1.2, 1.3, 1.4]
    assert ros1.provenance.path == str((tmp_path / "r.bag").resolve())
    assert ros2.metadata["format"] == "rosbag2"
    (tmp_path / "c.log").write_text(CLF + "\n")
    clf = load_file(tmp_path / "c.log", {"max_range": 1.5})
    assert clf.metadata["format"] == "carmen-raw" and clf.laser.max_range == 1.5
    assert [e.ranges[0] for e in clf.events if isinstance(e, LaserScan)] == [1.5, 1.5, 1.5]


def test_load_data_takes_names_then_paths(bags, tmp_path):
    assert load_data("five-features").name == "five-features"
    path = _bag(bags, tmp_path / "mine.bag")
    ds = load_data(str(path), options={"max_odom_gap": 1.0})
    assert ds.name == "mine.bag" and ds.provenance.options["max_odom_gap"] == 1.0
    assert "registered_as" not in ds.metadata
    with pytest.raises(UnknownNameError, match=r"unknown dataset 'no-such-set'"):
        load_data("no-such-set")


def test_data_label():
    assert data_label("five-features") == "five-features"
    assert data_label("/data/laser/rosbags/aces.bag") == "aces"
    assert data_label("logs/intel.log.gz") == "intel"
    assert data_label("recordings/run3/") == "run3"
    assert data_label("x/fr079.clf") == "fr079"


# ------------------------------------------------------------------------ LaserSpec.mounting
def test_laser_spec_mounting_is_validated_and_its_yaw_wrapped():
    angles = np.array([-0.5, 0.0, 0.5])
    assert LaserSpec(angles, 10.0).mounting == (0.0, 0.0, 0.0)
    spec = LaserSpec(angles, 10.0, mounting=(0.04, -0.01, 4.0))
    assert spec.mounting[:2] == (0.04, -0.01)
    assert spec.mounting[2] == pytest.approx(4.0 - 2 * math.pi, abs=1e-15)
    with pytest.raises(InputError, match=r"laser mounting: expected three numbers"):
        LaserSpec(angles, 10.0, mounting=(0.0, 0.0))  # type: ignore[arg-type]
    with pytest.raises(NonFiniteError, match=r"laser mounting: expected finite"):
        LaserSpec(angles, 10.0, mounting=(0.0, math.nan, 0.0))


# ------------------------------------------------------------------------ slamkit run --data PATH
def test_cli_runs_dead_reckoning_on_a_bag_and_records_the_path(bags, tmp_path):
    path = _bag(bags, tmp_path / "mine.bag")
    cfg = tmp_path / "c.toml"
    cfg.write_text("[dataset]\nmax_odom_gap = 2.0\nodometry_sigma_trans = 0.1\n")
    out = tmp_path / "out"
    res = runner.invoke(
        app,
        ["run", "dead-reckoning", "--data", str(path), "--config", str(cfg), "--out", str(out),
         "--no-plots"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    config = json.loads((out / "config.json").read_text())
    assert config["dataset"]["path"] == str(path.resolve())
    assert config["dataset"]["name"] == "mine.bag" and config["dataset"]["max_odom_gap"] == 2.0
    # dead reckoning from the first odometry pose reproduces the odometry at the scans
    t, poses = read_tum(out / "trajectory.tum")
    ds = load_file(path)
    odom = np.array([e.pose for e in ds.events if isinstance(e, Odometry)])
    np.testing.assert_allclose(t, [1.0, 1.1, 1.2, 1.3, 1.4], atol=1e-9)
    np.testing.assert_allclose(poses, odom, atol=1e-9)
    # config.json feeds a rerun: its [dataset] path and name are informational
    rerun = tmp_path / "rerun.json"
    rerun.write_text(json.dumps({"dataset": config["dataset"], "seed": 0}))
    res = runner.invoke(
        app,
        ["run", "dead-reckoning", "--data", str(path), "--config", str(rerun), "--out",
         str(tmp_path / "o2"), "--no-plots"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output


def test_cli_runs_on_a_carmen_log_and_names_the_output_after_it(tmp_path, monkeypatch):
    (tmp_path / "run.clf").write_text(CLF + "\n")
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["run", "dead-reckoning", "--data", "run.clf", "--no-plots"])
    assert res.exit_code == 0, res.output
    t, poses = read_tum(tmp_path / "results" / "dead-reckoning-run" / "trajectory.tum")
    np.testing.assert_allclose(t, [10.0, 11.0, 12.0])
    np.testing.assert_allclose(poses[:, 0], [0.0, 0.1, 0.2], atol=1e-12)


def test_cli_unknown_format_is_one_line_with_the_formats(tmp_path):
    (tmp_path / "scan.xyz").write_text("1,2\n")
    res = runner.invoke(app, ["run", "dead-reckoning", "--data", str(tmp_path / "scan.xyz")])
    assert res.exit_code == 1
    assert "unknown kind of file '.xyz'" in res.output and "CARMEN .clf/.log" in res.output
    assert "landmark data .csv" in res.output


# ------------------------------------------------------------------------ a registered bag's path
@pytest.mark.realdata
def test_a_registered_bags_path_reads_as_the_registered_data_set(data_root):
    bag = data_root / "laser" / "rosbags" / "aces.bag"
    if not bag.exists():
        pytest.skip(f"real data not found: {bag}")
    by_path = load_data(str(bag), data_root=data_root)
    by_name = load_data("aces-raw", data_root=data_root)
    assert by_path.provenance.registered_as == "aces-raw"
    assert by_path.provenance.options["max_odom_gap"] == 3.5
    assert [e.t for e in by_path.events] == [e.t for e in by_name.events]
    assert by_path.truth.relations is None and by_name.truth.relations is not None
