"""The HTML of run and comparison pages: what they hold, escaping, and bad folders."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from slamkit.errors import InputError
from slamkit.report import (
    RunPage,
    compare_html,
    flatten_metrics,
    order_figures,
    read_run_folder,
    run_html,
)


def _folder(root: Path, name: str, rmse: float) -> Path:
    run = root / name
    run.mkdir()
    metrics = {
        "estimator": "ekf-slam",
        "dataset": "five<features>",
        "seed": 3,
        "steps": 10,
        "runtime": {"total_seconds": 1.5, "mean_step_seconds": 0.15, "max_step_seconds": 0.4},
        "ate": {"rmse": rmse, "max": 2 * rmse},
        "gps": {"skipped": "no GPS & no fix"},
        "per_step": list(range(100)),
    }
    (run / "metrics.json").write_text(json.dumps(metrics))
    (run / "config.json").write_text(json.dumps({"estimator": {"name": "ekf-slam"}, "seed": 3}))
    for fig in ("nees.png", "trajectory.png", "zeta.png", "errors.png", "trajectory.svg"):
        (run / fig).write_bytes(b"")
    return run


def test_flatten_metrics_keeps_order_and_marks_skipped() -> None:
    metrics = {"estimator": "x", "ate": {"rmse": 0.12345, "n": 7}, "gps": {"skipped": "none"}}
    rows = flatten_metrics({**metrics, "big": 1.0e7, "v": [1, 2, 3, 4, 5]})
    assert list(rows) == ["ate.rmse", "ate.n", "gps", "big", "v"]
    assert rows["ate.rmse"] == "0.1235"
    assert rows["ate.n"] == "7"
    assert rows["gps"] == "skipped: none"
    assert rows["big"] == "1.000e+07"
    assert rows["v"] == "[5 values]"


def test_order_figures_puts_the_trajectory_first() -> None:
    names = ["nis.png", "b.png", "trajectory.png", "a.txt", ".hidden.png", "map.png"]
    assert order_figures(names) == ("trajectory.png", "map.png", "nis.png", "b.png")


def test_run_page_holds_figures_metrics_config_and_escapes(tmp_path: Path) -> None:
    page = read_run_folder(
        _folder(tmp_path, "r", 0.5),
        estimator_description="EKF <SLAM>",
        timings={"load the data set": 0.25},
    )
    assert page.figures == ("trajectory.png", "errors.png", "nees.png", "zeta.png")
    text = run_html(page)
    assert text.count("<img ") == 4
    assert '<img src="trajectory.png"' in text  # relative to the folder
    assert "five&lt;features&gt;" in text and "five<features>" not in text
    assert "EKF &lt;SLAM&gt;" in text
    assert "skipped: no GPS &amp; no fix" in text
    assert ">0.25" in text and "load the data set" in text
    assert text.index("trajectory.png") < text.index("errors.png")
    assert "&quot;seed&quot;: 3" in text  # the config, escaped in a <pre>


def test_compare_page_has_a_column_per_run(tmp_path: Path) -> None:
    pages = [read_run_folder(_folder(tmp_path, n, r)) for n, r in (("a", 0.5), ("b", 0.25))]
    text = compare_html(pages, tmp_path / "out")
    assert text.count("<img ") == 8
    assert 'src="../a/trajectory.png"' in text and 'src="../b/trajectory.png"' in text
    row = text[text.index("<th>ate.rmse</th>") :].split("</tr>", 1)[0]
    assert ">0.5<" in row and ">0.25<" in row


def test_bad_folders_are_named(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"no metrics\.json"):
        read_run_folder(tmp_path)
    with pytest.raises(InputError, match="not a folder"):
        read_run_folder(tmp_path / "nope")
    (tmp_path / "metrics.json").write_text("[1, 2]")
    with pytest.raises(InputError, match="expected a JSON object"):
        read_run_folder(tmp_path)
    with pytest.raises(InputError, match="at least one"):
        compare_html([], tmp_path)


def test_page_without_figures_says_so(tmp_path: Path) -> None:
    page = RunPage(tmp_path, "dead-reckoning", "five-features", metrics={"seed": 0})
    assert "no figures" in run_html(page)
    assert "Warnings" not in run_html(page)


def test_consistency_warnings_are_listed_on_the_page(tmp_path: Path) -> None:
    message = "NEES inconsistent (over-confident): mean 7.2e+06 over steps 0-49 <b>"
    metrics = {"seed": 0, "warnings": [{"statistic": "nees", "message": message}]}
    text = run_html(RunPage(tmp_path, "ekf-localization", "five-features", metrics=metrics))
    assert "<h2>Warnings</h2>" in text
    assert (
        '<ul id="warnings"><li>NEES inconsistent (over-confident): mean 7.2e+06 over steps' in text
    )
    assert "&lt;b&gt;</li>" in text  # escaped


def test_run_page_says_what_reading_the_data_did_and_lists_every_warning(tmp_path: Path) -> None:
    run = _folder(tmp_path, "r", 0.5)
    metrics = json.loads((run / "metrics.json").read_text())
    metrics["reading"] = {
        "file": "intel.log",
        "what": "scans",
        "records": 912,
        "used": 910,
        "dropped": {"FLASER: a field is not a number": 2},
        "repaired": {"stamps out of order": 4},
        "notes": ["PARAM laser_front_laser_fov 3.14159 read as radians (180° at 1°)"],
    }
    metrics["warnings"] = [
        {"kind": "odometry_glitches", "message": "3 odometry glitches overridden at 12.5 s"},
        {"message": "NEES above its band over 40 s"},
    ]
    (run / "metrics.json").write_text(json.dumps(metrics))
    text = run_html(read_run_folder(run))
    section = text[text.index("<h2>Reading the data</h2>") : text.index("<h2>Figures</h2>")]
    assert (
        '<p id="reading">read intel.log: 910 of 912 scans; dropped 2 FLASER: a field is not a '
        "number<br>repaired 4 stamps out of order; PARAM laser_front_laser_fov 3.14159 read as "
        "radians (180° at 1°)</p>"
    ) in section
    assert "<th>dropped</th><td>FLASER: a field is not a number</td>" in section
    assert "<th>repaired</th><td>stamps out of order</td>" in section
    assert '<ul id="reading-notes"><li>PARAM laser_front_laser_fov' in section
    assert "more than 10% of a file" in section
    # Not also in the metrics table as dotted keys.
    assert "reading.dropped" not in text and "reading.repaired" not in text
    table = text[text.index('<div id="metrics">') :].split("</div>", 1)[0]
    assert "reading" not in table and "warnings" not in table
    # Both kinds of warning are listed, the estimator's kind as the tooltip.
    assert '<li title="odometry_glitches">3 odometry glitches overridden at 12.5 s</li>' in text
    assert "<li>NEES above its band over 40 s</li>" in text
    # The comparison page has the reading as one row in words.
    assert flatten_metrics(metrics)["reading"] == "910 of 912 scans, 2 dropped, 4 repaired, 1 note"


def test_a_clean_reading_is_one_line_and_a_malformed_one_is_refused(tmp_path: Path) -> None:
    run = _folder(tmp_path, "r", 0.5)
    metrics = json.loads((run / "metrics.json").read_text())
    metrics["reading"] = {"file": "a.bag", "records": 5, "used": 5}
    (run / "metrics.json").write_text(json.dumps(metrics))
    text = run_html(read_run_folder(run))
    assert '<p id="reading">read a.bag: 5 of 5 scans</p>' in text
    assert "reading-counts" not in text
    metrics["reading"] = {"file": "a.bag", "records": "five", "used": 5}
    (run / "metrics.json").write_text(json.dumps(metrics))
    with pytest.raises(InputError, match=r"reading\.records"):
        read_run_folder(run)


def test_the_estimators_counts_have_a_table_of_their_own_in_words() -> None:
    """``diagnostics`` is not a block of dotted keys in the metrics table: it has its own
    table, each key in words (``loops rejected › refine: degenerate``)."""
    from slamkit.report.html import RunPage

    metrics = {
        "ate": {"rmse": 0.05},
        "diagnostics": {"keyframes": 12, "loops_rejected": {"refine:degenerate": 3}},
    }
    text = run_html(RunPage(Path("."), "graph-slam", "loop", metrics=metrics))
    table = text[text.index('<div id="metrics">') :].split("</div>", 1)[0]
    assert "ate.rmse" in table and "diagnostics" not in table
    counts = text[text.index('<table id="diagnostics">') :].split("</table>", 1)[0]
    assert "<th>keyframes</th>" in counts and ">12<" in counts
    assert "loops rejected › refine: degenerate" in counts and ">3<" in counts
