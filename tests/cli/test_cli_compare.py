"""`slamkit run --svg` and `slamkit compare DIR...`: the files, the page, the table, the CSV,
the errors."""

from __future__ import annotations

import csv
import json

from typer.testing import CliRunner

from slamkit.cli.main import app

runner = CliRunner()


def test_run_then_compare_two_runs(tmp_path):
    for seed in ("0", "1"):
        res = runner.invoke(
            app,
            [
                "run",
                "dead-reckoning",
                "--seed",
                seed,
                "--svg",
                "--out",
                str(tmp_path / f"dr{seed}"),
            ],
        )
        assert res.exit_code == 0, res.output
        assert "report.html" in res.output
    run0 = tmp_path / "dr0"
    for name in ("trajectory", "errors", "nees"):
        assert (run0 / f"{name}.svg").read_bytes().lstrip()[:5] in (b"<?xml", b"<svg ")
    page = (run0 / "report.html").read_text()
    assert page.count("<img ") == 3  # the PNGs; the SVG copies are in the file list
    assert 'href="trajectory.svg"' in page
    res = runner.invoke(
        app, ["compare", str(run0), str(tmp_path / "dr1"), "--out", str(tmp_path / "cmp")]
    )
    assert res.exit_code == 0, res.output
    text = (tmp_path / "cmp" / "compare.html").read_text()
    assert text.count("<img ") == 6
    assert 'src="../dr1/errors.png"' in text


def test_compare_of_a_folder_that_is_not_a_run_is_one_line(tmp_path):
    res = runner.invoke(app, ["compare", str(tmp_path), "--out", str(tmp_path / "cmp")])
    assert res.exit_code == 1
    assert "no metrics.json" in res.output
    assert "Traceback" not in res.output


def test_compare_prints_a_row_a_run_and_writes_every_metric_as_csv(tmp_path):
    folders = []
    for estimator in ("dead-reckoning", "ekf-localization"):
        out = tmp_path / estimator
        res = runner.invoke(app, ["run", estimator, "--out", str(out), "--no-plots"])
        assert res.exit_code == 0, res.output
        folders.append(out)
    csv_path = tmp_path / "tables" / "runs.csv"
    res = runner.invoke(
        app,
        ["compare", *map(str, folders), "--out", str(tmp_path / "cmp"), "--csv", str(csv_path)],
        env={"COLUMNS": "250"},
    )
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(csv_path.open()))
    assert [r["run"] for r in rows] == ["dead-reckoning", "ekf-localization"]
    lines = res.output.splitlines()
    for number, (row, folder) in enumerate(zip(rows, folders, strict=True), start=1):
        metrics = json.loads((folder / "metrics.json").read_text())
        assert row["estimator"] == metrics["estimator"] and row["folder"] == str(folder)
        assert float(row["ate.rmse"]) == metrics["ate"]["rmse"]  # the file's number, exactly
        assert float(row["runtime.total_seconds"]) == metrics["runtime"]["total_seconds"]
        assert f"  {number}  {folder}" in lines  # the legend
        line = next(t for t in lines if t.startswith(f"│ {number:>3} │"))
        assert f"{metrics['ate']['rmse']:.4g}" in line  # the console row of this run
    assert "ATE RMSE, SE(2)-aligned [m]" in res.output
    # dead reckoning drifts; the EKF with landmarks does not
    assert float(rows[0]["ate.rmse"]) > float(rows[1]["ate.rmse"])
