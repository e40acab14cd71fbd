"""The relation-error plot and its place in a run's figures."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from slamkit.datasets import Relations, load_dataset
from slamkit.errors import ShapeError
from slamkit.eval import relation_errors
from slamkit.geometry.pose2 import between
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.viz import new_figure, plot_relation_errors
from slamkit.viz.report import run_figures


def test_plot_relation_errors_draws_each_relation_over_t1():
    times = np.array([1000.0, 1001.0, 1002.0])
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    rel = Relations(
        [1000.0, 1001.0, 1000.0],
        [1001.0, 1002.0, 1002.0],
        [[1.0, 0.0, 0.0], [1.2, 0.0, 0.0], [2.0, 0.0, np.radians(3.0)]],
    )
    scores = relation_errors(times, poses, rel)
    fig = new_figure()
    axes = fig.subplots(2, 1, sharex=True)
    drawn = plot_relation_errors(axes, scores)
    dots, mean = drawn[0]
    np.testing.assert_allclose(dots.get_xdata(), [0.0, 1.0, 0.0])  # t1 − first t1
    np.testing.assert_allclose(dots.get_ydata(), [0.0, 0.2, 0.0], atol=1e-12)
    np.testing.assert_allclose(mean.get_ydata(), [0.2 / 3, 0.2 / 3])
    np.testing.assert_allclose(drawn[1][0].get_ydata(), [0.0, 0.0, 3.0], atol=1e-12)
    assert axes[1].get_ylabel() == "rotational error [deg]"
    assert axes[1].get_xlabel() == "t1 − 1000.000 [s]"
    with pytest.raises(ShapeError):
        plot_relation_errors(axes[:1], scores)


def test_a_run_scored_against_relations_gets_relation_errors_png():
    ds = load_dataset("five-features", seed=0)
    assert ds.truth.times is not None and ds.truth.poses is not None
    t, x = ds.truth.times, ds.truth.poses
    i = np.arange(0, t.size - 10, 5)
    rel = Relations(t[i], t[i + 10], between(x[i], x[i + 10]))
    with_rel = replace(ds, truth=replace(ds.truth, relations=rel))
    res = run("dead-reckoning", with_rel)
    figs = run_figures(res, with_rel, evaluate(res, with_rel))
    assert "relation_errors.png" in figs
    dots = figs["relation_errors.png"].axes[0].lines[0]
    assert len(dots.get_xdata()) == i.size
    assert "relation_errors.png" not in run_figures(res, ds, evaluate(res, ds))
