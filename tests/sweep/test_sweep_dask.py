"""Sweeps on a LocalCluster of two worker processes: the same metrics as the same runs one
after another, nothing run twice, failures recorded, a killed worker survived."""

from __future__ import annotations

import math
import os
import signal
from pathlib import Path

import pytest
from typer.testing import CliRunner

from slamkit.app import RunRequest, run_job
from slamkit.cli.main import app
from slamkit.sweep import SweepProgress, parse_spec, read_table, run_sweep
from slamkit.sweep.table import flatten_metrics

distributed = pytest.importorskip("distributed")

SPEC = {
    "sweep": {
        "name": "small",
        "estimators": ["ekf-localization", "dead-reckoning"],
        "datasets": ["five-features"],
        "seeds": [0, 1],
    },
    "estimator": {"motion_cov_scale": [1.0, 2.0]},
}


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        silence_logs=50,
        env={"OPENBLAS_NUM_THREADS": "1"},
    )
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def _comparable(row):
    """Every metric but the wall-clock times."""
    return {
        k: v
        for k, v in row.items()
        if not k.startswith("runtime.") and not (isinstance(v, float) and math.isnan(v))
    }


def test_sweep_matches_sequential_runs_and_reruns_nothing(client, tmp_path):
    progress: list[SweepProgress] = []
    result = run_sweep(SPEC, tmp_path / "out", client=client, progress=progress.append)
    assert (result.total, result.executed, result.skipped, result.failed) == (8, 8, 0, 0)
    assert progress[-1].done == 8 and progress[-1].running == 0
    assert [p.done for p in progress] == list(range(9))
    rows = read_table(tmp_path / "out")
    assert len(rows) == 8 and {r["status"] for r in rows} == {"ok"}
    assert all((tmp_path / "out" / "runs" / r["key"] / "trajectory.tum").is_file() for r in rows)

    # the same runs one after another, in this process, through run_job as `slamkit run`
    points = parse_spec(SPEC).points()
    for point, row in zip(points, rows, strict=True):
        report = run_job(
            RunRequest(
                point.estimator,
                point.dataset,
                tmp_path / "seq" / row["key"],
                seed=point.seed,
                estimator_config=point.settings,
                plots=False,
            )
        )

        expected = _comparable(flatten_metrics(report.metrics))
        got = {k: v for k, v in _comparable(row).items() if k in expected}
        assert got == expected
        assert row["estimator.motion_cov_scale"] == point.settings["motion_cov_scale"]
        assert row["nees.mean"] > 0  # a real number, compared exactly above

    again = run_sweep(SPEC, tmp_path / "out", client=client)
    assert (again.executed, again.skipped) == (0, 8)
    assert [_comparable(r) for r in read_table(tmp_path / "out")] == [_comparable(r) for r in rows]


def test_failed_runs_are_recorded_and_do_not_stop_the_others(client, tmp_path):
    spec = {
        "sweep": {"estimators": ["dead-reckoning"], "datasets": ["five-features"]},
        "dataset": {"laps": [1, 0]},
    }
    result = run_sweep(spec, tmp_path, client=client)
    assert (result.executed, result.failed) == (2, 1)
    ok, bad = result.rows
    assert ok["status"] == "ok" and ok["ate.rmse"] > 0
    assert bad["status"] == "failed" and "laps" in bad["error"]
    assert "\n" not in bad["error"]
    assert (tmp_path / "failures" / f"{bad['key']}.json").is_file()
    again = run_sweep(spec, tmp_path, client=client)
    assert (again.executed, again.skipped, again.failed) == (0, 2, 1)


def test_cli_sweep_by_scheduler_address_and_report(client, tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text(
        '[sweep]\nname = "cli"\nestimators = ["ekf-localization"]\n'
        'datasets = ["five-features"]\nseeds = 3\n[estimator]\nmotion_cov_scale = [1.0, 4.0]\n'
    )
    out = tmp_path / "out"
    runner = CliRunner()
    res = runner.invoke(
        app, ["sweep", str(spec), "--out", str(out), "--scheduler", client.scheduler.address]
    )
    assert res.exit_code == 0, res.output
    assert "6 runs: 6 run now, 0 finished before, 0 failed" in res.output
    res = runner.invoke(app, ["sweep", "report", str(out)])
    assert res.exit_code == 0, res.output
    text = (out / "report" / "report.md").read_text()
    rows = read_table(out)
    nees = [r["nees.mean"] for r in rows if r["estimator.motion_cov_scale"] == 1.0]
    assert f"{sum(nees) / 3:.3f}" in text
    assert (out / "report" / "ate.rmse_vs_estimator.motion_cov_scale.png").is_file()
    bad = tmp_path / "bad.toml"
    bad.write_text('[sweep]\nestimators = ["ekf-localisation"]\ndatasets = ["five-features"]\n')
    res = runner.invoke(app, ["sweep", str(bad), "--out", str(tmp_path / "never")])
    assert res.exit_code == 1
    assert "ekf-localisation" in res.output
    assert not (tmp_path / "never").exists()


def test_a_killed_worker_has_its_run_retried(client, tmp_path):
    spec = {
        "sweep": {"estimators": ["ekf-localization"], "datasets": ["five-features"], "seeds": 6},
        "dataset": {"laps": 2},
    }
    killed: list[int] = []

    def kill_a_busy_worker(p: SweepProgress) -> None:
        if killed or p.done < 1:
            return
        pids = client.run(os.getpid)
        busy = [addr for addr, tasks in client.processing().items() if tasks]
        if busy:
            killed.append(pids[busy[0]])
            os.kill(pids[busy[0]], signal.SIGKILL)

    result = run_sweep(spec, tmp_path, client=client, progress=kill_a_busy_worker)
    assert killed, "no worker was busy to kill"
    assert (result.total, result.failed) == (6, 0)
    rows = read_table(tmp_path)
    assert [r["status"] for r in rows] == ["ok"] * 6
    assert sorted(r["seed"] for r in rows) == list(range(6))
    assert all(Path(tmp_path, "runs", r["key"], "metrics.json").is_file() for r in rows)
    assert not list((tmp_path / "runs").glob(".*.partial"))  # the killed run's partial folder


def test_a_finished_run_whose_result_was_lost_is_not_run_again(tmp_path):
    # When the worker holding a finished result dies, the scheduler recomputes the task:
    # the second attempt finds the run's folder complete and returns what it wrote.
    from slamkit.sweep.execute import RunTask, execute_task, plan_sweep

    spec = parse_spec({"sweep": {"estimators": ["dead-reckoning"], "datasets": ["five-features"]}})
    ((key, point),) = plan_sweep(spec)
    task = RunTask(key, point, str(tmp_path / key))
    first = execute_task(task)
    assert first.ok, first.error
    again = execute_task(task)
    assert again.ok, again.error
    assert again.metrics == first.metrics
    assert first.metrics["ate"]["rmse"] > 0


def test_a_sweep_over_a_log_file_given_by_its_path(client, tmp_path, carmen_log):
    log = carmen_log("run.log")  # a corrected CARMEN log: odometry = poses + seeded noise
    spec = {
        "sweep": {"estimators": ["dead-reckoning"], "datasets": [str(log)], "seeds": [0, 1]},
        "dataset": {"odometry_sigma_trans": [0.0, 0.05]},
    }
    result = run_sweep(spec, tmp_path / "out", client=client)
    assert (result.total, result.executed, result.failed) == (4, 4, 0), result.rows
    rows = read_table(tmp_path / "out")
    assert {r["dataset"] for r in rows} == {str(log.resolve())}
    assert all(r["reading.used"] == 6 for r in rows)
    # The option reached the reader: the same seed draws other odometry at each value.
    by_point = {(r["seed"], r["dataset.odometry_sigma_trans"]): r["ate.rmse"] for r in rows}
    assert len(by_point) == 4 and all(by_point[s, 0.0] != by_point[s, 0.05] for s in (0, 1))
