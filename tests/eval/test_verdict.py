"""A run's one-line verdict (slamkit.eval.verdict): its rules on findings made by hand, and
on runs — a clean simulated run looks consistent; one whose wheels glitch, or whose filter
is made over-confident, is doubtful and says why, on the console's line, in metrics.json
and on the report page."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from slamkit.datasets import load_dataset
from slamkit.datasets.stream import Dataset
from slamkit.estimation.contract import RunWarning
from slamkit.eval.verdict import CONSISTENT, verdict
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.report.html import RunPage, run_html


def test_the_rules_on_findings_made_by_hand() -> None:
    assert verdict([]).line == CONSISTENT and verdict([]).consistent
    glitch = RunWarning("odometry_glitches", "the wheels glitched 3 time(s)")
    lost = RunWarning("track_lost", "12 of 900 scans fit nowhere")

    @dataclasses.dataclass
    class Monitor:  # the shape of eval.monitor.ConsistencyWarning that the rules read
        statistic: str = "nees"
        direction: str = "over-confident"

    found = verdict([glitch, Monitor(), lost, glitch])
    assert not found.consistent
    assert found.reasons == ("odometry glitches", "NEES over-confident", "track lost")
    assert found.line == "doubtful: odometry glitches; NEES over-confident; track lost"
    assert found.as_dict() == {
        "consistent": False,
        "line": found.line,
        "reasons": list(found.reasons),
    }


@pytest.fixture(scope="module")
def loop_world() -> Dataset:
    return load_dataset("corridor-loop-laser", seed=0)


def _page(scores, estimator: str, dataset: str) -> str:
    metrics = scores.as_dict()
    page = RunPage(Path("."), estimator=estimator, dataset=dataset, metrics=metrics)
    return run_html(page)


def test_a_clean_run_looks_consistent_and_a_glitched_one_is_doubtful(
    loop_world, heading_jump
) -> None:
    clean = evaluate(run("graph-slam", loop_world, seed=0), loop_world).scores
    assert clean.verdict.line == CONSISTENT
    assert clean.as_dict()["verdict"] == {"consistent": True, "line": CONSISTENT, "reasons": []}
    assert 'id="verdict" class="consistent"' in _page(clean, "graph-slam", "loop")

    glitched, _ = heading_jump(loop_world, math.radians(60.0), 0.5)
    scores = evaluate(run("graph-slam", glitched, seed=0), glitched).scores
    assert not scores.verdict.consistent
    assert "odometry glitches" in scores.verdict.reasons
    assert scores.as_dict()["verdict"]["line"].startswith("doubtful: ")
    html = _page(scores, "graph-slam", "loop")
    assert 'id="verdict" class="doubtful"' in html and "odometry glitches" in html


def test_an_over_confident_filter_is_doubtful() -> None:
    data = load_dataset(
        "five-features", seed=0, options={"sigma_range": 1e-6, "sigma_bearing_deg": 1e-6}
    )
    scores = evaluate(run("ekf-localization", data, seed=0), data).scores
    assert scores.verdict.reasons[:1] == ("NEES over-confident",)
    nominal = load_dataset("five-features", seed=0)
    assert evaluate(run("ekf-localization", nominal, seed=0), nominal).scores.verdict.consistent
