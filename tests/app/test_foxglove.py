"""``slamkit run --mcap``: the MCAP file for Foxglove reads back with the ``mcap`` package, with
the expected topics, message counts and contents, every message shaped as its schema says."""

from __future__ import annotations

import base64
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.app import RunRequest, run_job
from slamkit.app.foxglove import SCHEMAS, TOPICS
from slamkit.cli.main import app
from slamkit.datasets import LaserScan, load_dataset
from slamkit.errors import InputError
from slamkit.geometry.pose2 import interpolate_poses
from slamkit.io import read_tum
from slamkit.maps import UNKNOWN
from slamkit.optim.data import loop_closures

pytest.importorskip("mcap", reason="the mcap package (pip install 'slamkit[mcap]') is absent")
from mcap.reader import make_reader

runner = CliRunner()


def _read(path: Path) -> tuple[dict[str, int], dict[str, list[tuple[int, dict[str, Any]]]]]:
    """Message counts from the summary and every message, by topic, checked against the
    channel's schema and encodings."""
    with path.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        counts = {
            ch.topic: summary.statistics.channel_message_counts[ch.id]
            for ch in summary.channels.values()
        }
        messages: dict[str, list[tuple[int, dict[str, Any]]]] = {}
        for schema, channel, message in reader.iter_messages():
            assert channel.message_encoding == "json" and schema is not None
            assert schema.encoding == "jsonschema" and schema.name == TOPICS[channel.topic]
            assert json.loads(schema.data) == SCHEMAS[schema.name]
            data = json.loads(message.data)
            _conforms(data, SCHEMAS[schema.name], channel.topic)
            messages.setdefault(channel.topic, []).append((message.log_time, data))
    return counts, messages


def _conforms(value: Any, schema: dict[str, Any], where: str) -> None:
    """``value`` has exactly the schema's properties, each of its type (recursively)."""
    kind = schema["type"]
    if kind == "object" and "properties" in schema:
        assert isinstance(value, dict) and set(value) == set(schema["properties"]), where
        for key, sub in schema["properties"].items():
            _conforms(value[key], sub, f"{where}.{key}")
    elif kind == "array":
        assert isinstance(value, list), where
        for k, item in enumerate(value[:50]):
            _conforms(item, schema["items"], f"{where}[{k}]")
    else:
        types = {"number": (int, float), "integer": (int,), "string": (str,), "boolean": (bool,),
                 "object": (dict,)}  # fmt: skip
        assert isinstance(value, types[kind]), where
        assert kind == "boolean" or not isinstance(value, bool), where


@pytest.fixture(scope="module")
def slam_run(tmp_path_factory):
    """graph-slam on rooms-laser (seed 0) with ``mcap="run.mcap"``: scans, path, graph with
    its loop closures, the map it built."""
    out = tmp_path_factory.mktemp("fox") / "slam"
    return run_job(RunRequest("graph-slam", "rooms-laser", out, plots=False, mcap=Path("run.mcap")))


def test_slam_run_mcap_topics_counts_and_contents(slam_run):
    counts, messages = _read(slam_run.out_dir / "run.mcap")
    dataset = load_dataset("rooms-laser", seed=0)
    scans = [e for e in dataset.events if isinstance(e, LaserScan)]
    times, poses = read_tum(slam_run.out_dir / "trajectory.tum")
    assert counts == {"/path": 1, "/truth/path": 1, "/graph": 1, "/map": 1,
                      "/tf": times.size, "/scan": len(scans)}  # fmt: skip
    assert "run.mcap" in slam_run.files
    # the path: every estimated pose, x, y and the heading's quaternion
    (_, path), = messages["/path"]  # fmt: skip
    xy = np.array([[p["position"]["x"], p["position"]["y"]] for p in path["poses"]])
    np.testing.assert_allclose(xy, poses[:, :2], atol=1e-6)
    q = path["poses"][-1]["orientation"]
    assert 2 * np.arctan2(q["z"], q["w"]) == pytest.approx(poses[-1, 2], abs=1e-6)
    # the graph: its consecutive edges and its loop closures, as line lists
    graph = slam_run.result.output.graph
    (_, update), = messages["/graph"]  # fmt: skip
    by_id = {e["id"]: e for e in update["entities"]}
    n_closures = len(loop_closures(graph))
    assert n_closures > 10
    assert by_id["graph/closures"]["metadata"] == [{"key": "count", "value": str(n_closures)}]
    assert len(by_id["graph/closures"]["lines"][0]["points"]) == 2 * n_closures
    n_edges = len(loop_closures(graph, min_gap=1)) - n_closures
    assert len(by_id["graph/edges"]["lines"][0]["points"]) == 2 * n_edges
    # the map: the run's grid, int8 percent, -1 where unknown, rows from the bottom
    grid = slam_run.result.output.grid
    (_, cells), = messages["/map"]  # fmt: skip
    percent = np.frombuffer(base64.b64decode(cells["data"]), dtype=np.int8)
    percent = percent.reshape(-1, cells["column_count"])
    assert percent.shape == grid.shape
    np.testing.assert_array_equal(percent == -1, grid.prob == UNKNOWN)
    known = grid.prob != UNKNOWN
    np.testing.assert_array_equal(percent[known], np.rint(100 * grid.prob[known]))
    assert cells["pose"]["position"]["x"] == pytest.approx(grid.origin_xy[0])
    # a scan: at the path's pose at its time, its stamp, no-return beams as 0
    k = len(scans) // 2
    t_ns, scan = messages["/scan"][k]
    assert t_ns == round(scans[k].t * 1e9)
    at = interpolate_poses(times, poses, np.array([scans[k].t]))[0]
    assert [scan["pose"]["position"][a] for a in "xy"] == pytest.approx(at[:2], abs=1e-6)
    assert scan["start_angle"] == pytest.approx(dataset.laser.beam_angles[0])
    no_return = scans[k].ranges >= dataset.laser.max_range
    np.testing.assert_allclose(
        np.array(scan["ranges"])[~no_return], scans[k].ranges[~no_return], atol=1e-4
    )
    assert np.all(np.array(scan["ranges"])[no_return] == 0.0)
    # the robot's frame at every estimate
    assert [m["child_frame_id"] for _, m in messages["/tf"][:1]] == ["base_link"]
    final = slam_run.result.poses[-1]
    assert messages["/tf"][-1][1]["translation"]["x"] == final[0]


def test_mcl_run_mcap_from_the_command_line_holds_the_known_map(tmp_path):
    """MCL keeps no graph and builds no map: the file has the map it localized in."""
    out = tmp_path / "mcl"
    res = runner.invoke(app, ["run", "mcl", "-d", "rooms-laser-global", "--no-plots",
                              "--out", str(out), "--mcap", "view.mcap"])  # fmt: skip
    assert res.exit_code == 0, res.output
    counts, messages = _read(out / "view.mcap")
    assert set(counts) == {"/path", "/truth/path", "/map", "/tf", "/scan"}
    grid = load_dataset("rooms-laser-global").known_grid
    (_, cells), = messages["/map"]  # fmt: skip
    assert cells["column_count"] == grid.shape[1]
    assert len(base64.b64decode(cells["data"])) == grid.prob.size


def test_without_the_mcap_package_the_run_stops_before_the_work(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "mcap.writer", None)  # import mcap.writer fails
    with pytest.raises(InputError, match=r"pip install 'slamkit\[mcap\]'"):
        run_job(RunRequest("mcl", "rooms-laser", tmp_path / "x", mcap=Path("a.mcap")))
    assert not (tmp_path / "x").exists()
