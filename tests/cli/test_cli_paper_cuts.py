"""Paper cuts of a first hour: bare data-set paths and default folders for ``optimize``, the
χ² of every iteration, the progress bar's rate and time left, help without type noise."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from rich.console import Console
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.cli.progress import progress_bar

runner = CliRunner()

# A square of four poses, 1 m sides, odometry slightly wrong, one loop closure.
SQUARE = """\
VERTEX_SE2 0 0 0 0
VERTEX_SE2 1 1.1 0 1.5708
VERTEX_SE2 2 1.1 1.1 3.1416
VERTEX_SE2 3 0 1.2 -1.5708
EDGE_SE2 0 1 1 0 1.5708 100 0 0 100 0 1000
EDGE_SE2 1 2 1 0 1.5708 100 0 0 100 0 1000
EDGE_SE2 2 3 1 0 1.5708 100 0 0 100 0 1000
EDGE_SE2 3 0 1 0 1.5708 100 0 0 100 0 1000
"""


def test_optimize_finds_a_bare_path_under_the_data_folder_and_writes_a_default_folder(
    tmp_path, monkeypatch
):
    data = tmp_path / "data"
    (data / "posegraph2d").mkdir(parents=True)
    (data / "posegraph2d" / "square.g2o").write_text(SQUARE)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setenv("SLAMKIT_DATA", str(data))
    res = runner.invoke(app, ["optimize", "posegraph2d/square.g2o", "--no-plots"])
    assert res.exit_code == 0, res.output
    out = work / "results" / "optimize-square"
    metrics = json.loads((out / "metrics.json").read_text())
    # One line per iteration with its χ²; the last one is the final χ² (the square is
    # consistent up to 1.5708 vs π/2: near zero), and χ² never rises over accepted steps.
    chi2 = [float(v) for v in re.findall(r"iteration +\d+ +χ² (\S+)", res.output)]
    assert len(chi2) == metrics["iterations"] >= 1
    assert chi2[-1] == pytest.approx(metrics["chi2_final"], rel=1e-5, abs=1e-9)
    # The file's vertices cost more than 1; the auto start takes the chordal one, below it.
    assert metrics["chi2_final"] < 1e-6 < 1.0 < metrics["start"]["costs"]["file"]
    assert metrics["chi2_initial"] == pytest.approx(metrics["start"]["costs"]["chordal"])
    assert np.all(np.diff(chi2) <= 1e-12)
    res = runner.invoke(app, ["optimize", "posegraph2d/nothing.g2o"])
    assert res.exit_code == 1 and "nothing.g2o: not found" in res.output
    assert str(data) in res.output


def test_the_progress_bar_shows_count_rate_and_time_left_never_none():
    console = Console(stderr=True, force_terminal=True, width=160, record=True)
    with progress_bar("job", "events", console) as progress:
        before = console.export_text(clear=False)
        progress(0, 0)  # a library that does not know its total yet
        progress.counting("scans")  # what the library counts, said before the first count
        for k in range(1, 40):
            progress(k, 40)
    text = console.export_text()
    assert "None" not in before + text
    assert "left" in text and "scans/s" in text and "scans 39/40" in text and "98%" in text


def test_the_steps_after_the_count_replace_the_bar_with_their_name():
    console = Console(stderr=True, force_terminal=True, width=160, record=True)
    with progress_bar("job", "events", console) as progress:
        for k in range(1, 41):
            progress(k, 40)
        progress.stage("writing 3 plots")
    text = console.export_text()
    # every render from the step's first on (at least that one and the last): its name and
    # elapsed time, and no frozen "0% … left 0:00:00" row of the finished count beside it
    after = text[text.index("job: writing 3 plots") :]
    assert after.count("job: writing 3 plots") >= 2 and "elapsed" in after
    assert "%" not in after and "left" not in after and "40/40" not in after


def test_help_lists_choices_and_shows_no_type_noise():
    for argv in (["eval", "ape", "--help"], ["run", "--help"], ["optimize", "--help"]):
        res = runner.invoke(app, argv, env={"COLUMNS": "200"})
        assert res.exit_code == 0, res.output
        assert "<bool>" not in res.output and "<str>" not in res.output, argv
    ape = runner.invoke(app, ["eval", "ape", "--help"], env={"COLUMNS": "200"}).output
    assert "none|se3|sim3|scale|se2" in ape and "auto|tum|kitti" in ape
    opt = runner.invoke(app, ["optimize", "--help"], env={"COLUMNS": "200"}).output
    assert "lm|gn|dogleg" in opt
