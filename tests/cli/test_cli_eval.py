"""``slamkit eval relations``: a TUM file against a relations file, its table, its JSON, its
errors; and the relation row of the run table."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.geometry.pose2 import compose
from slamkit.io import write_tum

runner = CliRunner()


def write_case(tmp_path):
    """A square drive (1 m forward, then a 90° turn, from a start facing +y) and three
    relations: exact, 0.1 m off sideways, 2° off."""
    poses = [np.array([1.0, 2.0, math.pi / 2])]
    for step in ([1.0, 0.0, 0.0], [1.0, 0.0, math.pi / 2], [0.5, 0.0, 0.0]):
        poses.append(compose(poses[-1], step))
    traj = tmp_path / "traj.tum"
    write_tum(traj, [100.0, 101.0, 102.0, 103.0], np.stack(poses))
    rel = tmp_path / "run.relations"
    rel.write_text(
        "100.0 101.0 1.0 0.0 0 0 0 0.0\n"
        f"101.0 102.0 1.0 0.1 0 0 0 {math.pi / 2!r}\n"
        f"102.0 103.0 0.5 0.0 0 0 0 {math.radians(2.0)!r}\n"
        "200.0 201.0 0.5 0.0 0 0 0 0.0\n"  # after the trajectory: not covered
    )
    return traj, rel


def test_eval_relations_prints_the_table_and_writes_json(tmp_path):
    traj, rel = write_case(tmp_path)
    out = tmp_path / "scores.json"
    res = runner.invoke(app, ["eval", "relations", str(traj), str(rel), "--json", str(out)])
    assert res.exit_code == 0, res.output
    # trans [0, 0.1, 0]: mean 0.0333, sample std 0.0577; rot [0, 0, 2]°: 0.667 ± 1.155.
    assert "3 / 4" in res.output and "75.0" in res.output
    assert "0.0333 ± 0.0577" in res.output
    assert "0.667 ± 1.155" in res.output
    assert "translational error [m]" in res.output
    data = json.loads(out.read_text())
    assert data["trajectory"] == str(traj) and data["relations_file"] == str(rel)
    r = data["relations"]
    assert r["count"] == 3 and r["total"] == 4 and r["covered_fraction"] == 0.75
    # write_tum keeps 9 significant digits: the 0.1 m comes back to 1e-8.
    assert r["translation_mean"] == pytest.approx(0.1 / 3, abs=1e-7)
    assert r["translation_std"] == pytest.approx(0.1 / math.sqrt(3), abs=1e-7)
    assert r["rotation_mean_deg"] == pytest.approx(2.0 / 3, abs=1e-6)
    assert r["translation_sq_mean"] == pytest.approx(0.01 / 3, abs=1e-8)
    assert r["rotation_sq_mean_deg"] == pytest.approx(4.0 / 3, abs=1e-5)


def test_eval_relations_max_duration(tmp_path):
    traj, rel = write_case(tmp_path)
    out = tmp_path / "s.json"
    res = runner.invoke(
        app, ["eval", "relations", str(traj), str(rel), "--max-duration", "0.5", "--json", str(out)]
    )
    assert res.exit_code == 1
    assert "none of the 4 relations" in res.output
    res = runner.invoke(
        app, ["eval", "relations", str(traj), str(rel), "--max-duration", "2", "--json", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert json.loads(out.read_text())["relations"]["max_duration"] == 2.0


@pytest.mark.parametrize(
    "make,message",
    [
        (lambda p: None, "missing.tum: not found"),
        (lambda p: p.write_text("100.0 1 2 3\n"), "expected 8 numbers, got 4"),
        (lambda p: p.write_bytes(b"\xff\xfe\x00binary"), "not UTF-8 text"),
        (
            lambda p: write_tum(p, [0.0, 1.0], np.zeros((2, 3))),
            "covers no relation",
        ),
    ],
)
def test_eval_relations_errors_are_one_line_with_exit_code_1(tmp_path, make, message):
    _, rel = write_case(tmp_path)
    traj = tmp_path / "missing.tum"
    make(traj)
    res = runner.invoke(app, ["eval", "relations", str(traj), str(rel)])
    assert res.exit_code == 1
    assert message in res.output
    assert "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1


def test_eval_relations_missing_relations_file(tmp_path):
    traj, _ = write_case(tmp_path)
    res = runner.invoke(app, ["eval", "relations", str(traj), str(tmp_path / "no.relations")])
    assert res.exit_code == 1 and "no.relations: not found" in res.output


def test_run_table_metrics_and_plot_carry_the_relations(tmp_path, monkeypatch):
    """``slamkit run`` on a data set given reference relations (here: the true motion over
    20 steps) shows them in its table, metrics.json and relation_errors.png."""
    from dataclasses import replace

    import slamkit.app.jobs as jobs
    from slamkit.datasets import Relations
    from slamkit.geometry.pose2 import between

    load = jobs.load_data

    def with_relations(*args, **kwargs):
        ds = load(*args, **kwargs)
        t, x = ds.truth.times, ds.truth.poses
        i = np.arange(0, t.size - 20, 10)
        rel = Relations(t[i], t[i + 20], between(x[i], x[i + 20]))
        return replace(ds, truth=replace(ds.truth, relations=rel))

    monkeypatch.setattr(jobs, "load_data", with_relations)
    out = tmp_path / "dr"
    res = runner.invoke(
        app, ["run", "dead-reckoning", "--data", "five-features", "--seed", "3", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    metrics = json.loads((out / "metrics.json").read_text())
    r = metrics["relations"]
    assert r["covered_fraction"] == 1.0 and r["count"] == r["total"] > 10
    assert r["translation_mean"] > 0
    lines = res.output.splitlines()
    (trans,) = [s for s in lines if "relation error, translation [m]" in s]
    assert f"{r['translation_mean']:.3f} ± {r['translation_std']:.3f}" in trans
    (rot,) = [s for s in lines if "relation error, rotation [deg]" in s]
    assert f"{r['rotation_mean_deg']:.1f} ± {r['rotation_std_deg']:.1f}" in rot
    (cov,) = [s for s in lines if "relations covered [%]" in s]
    assert "100" in cov
    assert (out / "relation_errors.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
