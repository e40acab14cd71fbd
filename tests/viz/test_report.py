"""The standard figures of a run, including particle clouds and NIS windows."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets import load_dataset
from slamkit.pipeline import EstimatorOutput, InnovationLog, ParticleSnapshot, run
from slamkit.pipeline.evaluate import evaluate
from slamkit.viz.report import run_figures


def test_run_figures_include_particles_and_nis_when_the_estimator_provides_them():
    ds = load_dataset("five-features", seed=0)
    res = run("dead-reckoning", ds)
    rng = np.random.default_rng(0)
    k = 400
    log = InnovationLog(
        times=np.linspace(0, 30, k), nis=rng.chisquare(2, k), dof=np.full(k, 2),
        landmark_ids=np.zeros(k, dtype=np.int64),
    )  # fmt: skip
    snaps = tuple(
        ParticleSnapshot(float(t), ds.truth.poses[i] + rng.normal(0, 0.2, (300, 3)),
                         np.full(300, 1 / 300))
        for i, t in ((0, 0.0), (100, 10.0), (200, 20.0))
    )  # fmt: skip
    res = type(res)(
        **{**res.__dict__, "output": EstimatorOutput(innovations=log, particle_snapshots=snaps)}
    )
    ev = evaluate(res, ds)
    assert ev.metrics["nis"]["count"] == k and ev.metrics["nis"]["windows"] == 8
    assert abs(ev.metrics["nis"]["mean_nis_per_dof"] - 1.0) < 0.15
    figs = run_figures(res, ds, ev)
    assert set(figs) == {"trajectory.png", "errors.png", "nees.png", "particles.png", "nis.png"}
    # Three snapshots: three visible panels with one particle scatter each.
    visible = [ax for ax in figs["particles.png"].axes if ax.get_visible()]
    assert len(visible) == 3
    offsets = visible[1].collections[-1].get_offsets()
    assert offsets.shape == (300, 2)
    np.testing.assert_allclose(np.mean(offsets, axis=0), ds.truth.poses[100, :2], atol=0.05)
    # The map figure shows the last cloud too (FastSLAM: the poses behind the maps).
    labels = [c.get_label() for c in figs["trajectory.png"].axes[0].collections]
    assert "particles at t = 20.0 s" in labels


def test_the_errors_figure_draws_a_band_only_with_a_covariance() -> None:
    """Graph SLAM has no covariance: its errors figure plots the errors after the ATE's
    SE(2) alignment (their RMS is the headline ATE) and no band, and says so; an EKF's
    plots its unaligned errors with the ±3σ band."""
    ds = load_dataset("corridor-loop-laser", seed=0)
    res = run("laser-odometry", ds)
    ev = evaluate(res, ds)
    assert ev.sigmas is None and ev.aligned_errors is not None
    ate = ev.scores.ate
    assert np.sqrt(np.mean(np.sum(ev.aligned_errors[:, :2] ** 2, axis=1))) == pytest.approx(
        ate.rmse, rel=1e-9
    )
    fig = run_figures(res, ds, ev)["errors.png"]
    title = fig.axes[0].get_title()
    assert "alignment of the ATE" in title and "σ" in title and "±" not in title
    drawn = fig.axes[0].lines[0].get_ydata()
    np.testing.assert_allclose(drawn, ev.aligned_errors[:, 0])
    assert not fig.axes[0].collections  # no band

    five = load_dataset("five-features", seed=0)
    ekf = run("ekf-localization", five)
    ev = evaluate(ekf, five)
    assert ev.sigmas is not None
    fig = run_figures(ekf, five, ev)["errors.png"]
    assert "no alignment" in fig.axes[0].get_title() and "±3σ" in fig.axes[0].get_title()
    np.testing.assert_allclose(fig.axes[0].lines[0].get_ydata(), ev.errors[:, 0])
    assert fig.axes[0].collections  # the band


def test_on_data_without_truth_the_path_is_coloured_by_time_with_its_closures() -> None:
    """The user's own log (no truth): trajectory.png is not the map view again but the path
    coloured by the time since the start (with a colour bar) and the graph's loop
    closures, one red line each; with the truth it stays the estimate over the truth."""
    import dataclasses

    from matplotlib.collections import LineCollection

    from slamkit.datasets.stream import GroundTruth
    from slamkit.optim.data import loop_closures

    ds = load_dataset("corridor-loop-laser", seed=0)
    own = dataclasses.replace(ds, truth=GroundTruth())
    res = run("graph-slam", own)
    assert res.output.graph is not None
    closures = loop_closures(res.output.graph)
    assert closures.shape[0] > 0
    fig = run_figures(res, own, evaluate(res, own))["trajectory.png"]
    ax, bar = fig.axes
    assert bar.get_ylabel() == "time since the start [s]"
    collections = [c for c in ax.collections if isinstance(c, LineCollection)]
    path = next(c for c in collections if c.get_array() is not None)
    times = np.asarray(path.get_array())
    assert len(path.get_segments()) == len(res) - 1 and np.all(np.diff(times) >= 0)
    assert times[-1] == pytest.approx(res.times[-1] - res.times[0], rel=0.05)
    red = [c for c in collections if c.get_label().startswith("loop closures")]
    assert len(red) == 1 and len(red[0].get_segments()) == closures.shape[0]

    with_truth = run_figures(res, ds, evaluate(res, ds))["trajectory.png"]
    assert len(with_truth.axes) == 1  # no colour bar: the estimate over the truth
