"""A run recorded with rerun and read back with rerun's own reader: the logged poses are the
run's poses, the landmarks the map's, the scans and the occupancy map are there."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from slamkit.datasets import load_dataset
from slamkit.pipeline import run

rr = pytest.importorskip("rerun", reason="the rerun extra (rerun-sdk) is not installed")

from slamkit.app.recording import record_run  # noqa: E402


def _read(path):
    """Entity path -> (rows logged, the positions of every row) of the ``.rrd`` file."""
    from rerun.chunk import RrdReader

    out: dict[str, list[np.ndarray]] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.endswith("Points2D:positions"):
                for row in batch.column(name).to_pylist():
                    if row is not None:
                        out.setdefault(chunk.entity_path, []).append(np.array(row, float))
    return out


def test_ekf_slam_recording_holds_poses_and_landmarks(tmp_path):
    data = load_dataset("five-features", seed=0)
    data = dataclasses.replace(data, events=data.events[:300])
    result = run("ekf-slam", data, seed=0)
    path = tmp_path / "run.rrd"
    record_run(result, data, path)
    logged = _read(path)
    poses = logged["/world/estimate/pose"]
    assert len(poses) == len(result.poses)
    got = np.concatenate(poses)
    np.testing.assert_allclose(got, result.poses[:, :2], atol=1e-6)
    mapped = result.output.landmarks
    assert mapped is not None
    assert np.concatenate(logged["/world/landmarks"]).shape[0] == len(mapped.landmarks.positions)


def test_laser_recording_holds_scans_and_map(tmp_path):
    data = load_dataset("rooms-laser", seed=0)
    data = dataclasses.replace(data, events=data.events[:200])
    result = run("grid-rbpf", data, seed=0, config={"particles": 5})
    path = tmp_path / "run.rrd"
    record_run(result, data, path)
    logged = _read(path)
    assert len(logged["/world/estimate/pose"]) == len(result.poses)
    assert sum(p.shape[0] for p in logged["/world/scan"]) > 0
    grid = result.output.grid
    assert grid is not None
    occupied = int((grid.prob >= 0.65).sum())
    assert occupied > 0
    assert np.concatenate(logged["/world/map"]).shape[0] == occupied


def test_run_job_writes_the_recording_inside_its_folder(tmp_path):
    from slamkit.app import RunRequest, run_job

    report = run_job(
        RunRequest("ekf-slam", "five-features", tmp_path / "out", plots=False, rerun="run.rrd")
    )
    assert "run.rrd" in report.files
    logged = _read(tmp_path / "out" / "run.rrd")
    assert len(logged["/world/estimate/pose"]) == len(report.result.poses)


def _strips(path, entity):
    """The line strips logged at ``entity`` of the ``.rrd`` file."""
    from rerun.chunk import RrdReader

    out = []
    for chunk in RrdReader(path).stream().to_chunks():
        if chunk.entity_path != entity:
            continue
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.endswith("LineStrips2D:strips"):
                for row in batch.column(name).to_pylist():
                    if row is not None:
                        out.extend(np.array(strip, float) for strip in row)
    return out


def test_graph_recording_holds_edges_and_loop_closures(tmp_path):
    """graph-slam's pose graph: one segment per edge between consecutive poses and one per
    loop closure, between the poses they join (the same as the MCAP file's /graph)."""
    from slamkit.optim.data import loop_closures

    data = load_dataset("rooms-laser", seed=0)
    result = run("graph-slam", data, seed=0)
    path = tmp_path / "run.rrd"
    record_run(result, data, path)
    graph = result.output.graph
    closures = loop_closures(graph)
    logged = _strips(path, "/world/graph/closures")
    assert len(logged) == len(closures) > 10
    np.testing.assert_allclose(logged[0], graph.poses[closures[0], :2], atol=1e-5)
    edges = len(loop_closures(graph, min_gap=1)) - len(closures)
    assert len(_strips(path, "/world/graph/edges")) == edges


def test_mcl_recording_holds_the_map_it_localized_in(tmp_path):
    data = load_dataset("rooms-laser-global", seed=0)
    data = dataclasses.replace(data, events=data.events[:100])
    result = run("mcl", data, seed=0)
    assert result.output.grid is None
    path = tmp_path / "run.rrd"
    record_run(result, data, path)
    occupied = int((data.known_grid.prob >= 0.65).sum())
    assert np.concatenate(_read(path)["/world/map"]).shape[0] == occupied
