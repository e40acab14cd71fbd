"""GPS fused into the landmark graph (:mod:`slamkit.slam.landmark_graph`) on a simulated drive
with known truth: the lever arm is recovered and the outliers are down-weighted."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from slamkit.errors import ConfigError, InputError
from slamkit.optim import optimize
from slamkit.optim.gps import GpsWeighting, reweight
from slamkit.optim.marginals import marginal_covariances
from slamkit.sim.scenarios import build_landmark_clutter, build_landmark_loop
from slamkit.slam.landmark_graph import (
    GpsFixes,
    LandmarkGraphConfig,
    antenna_positions,
    build_landmark_graph,
    fuse_gps,
    odometry_segments,
)

LEVER = np.array([1.5, -0.4])  # the true antenna position in the robot frame [m]
SIGMA = 0.3  # GPS noise per axis [m]
N_OUT = 8  # outliers: fixes moved 15-30 m (multipath jumps)


def _drive_with_gps(seed: int):
    rng = np.random.default_rng(seed)
    ds = build_landmark_loop({}, seed=seed)
    times, poses = ds.truth.times, ds.truth.poses
    assert times is not None and poses is not None
    take = np.arange(1, times.shape[0], 5)  # a fix every fifth step
    t = times[take]
    xy = antenna_positions(poses[take], LEVER) + rng.normal(0.0, SIGMA, (t.shape[0], 2))
    out = rng.choice(t.shape[0], N_OUT, replace=False)
    ang = rng.uniform(0, 2 * np.pi, N_OUT)
    xy[out] += rng.uniform(15.0, 30.0, N_OUT)[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1)
    return ds, GpsFixes(t, xy, sigma=SIGMA), out


def test_odometry_segments_chain_to_the_dead_reckoning() -> None:
    """Integrating between nodes and chaining the segments is the same as integrating every
    control in turn (the model's own step): the cut pieces add up."""
    ds = build_landmark_loop({}, seed=1)
    built = build_landmark_graph(ds)
    assert ds.motion is not None and ds.initial_pose is not None
    x = np.array(ds.initial_pose, dtype=float)
    ctrl = [e for e in ds.events if type(e).__name__ == "Control"]
    for c in ctrl:
        x = ds.motion.model.apply(x, c.u, c.dt)
    np.testing.assert_allclose(built.initial_poses[-1, :2], x[:2], atol=1e-9)
    rel, cov = odometry_segments(ds, built.times[:3])
    assert rel.shape == (2, 3) and cov.shape == (2, 3, 3)
    assert np.all(np.linalg.eigvalsh(cov) > -1e-15)


@pytest.mark.parametrize("seed", [1, 2])
def test_lever_arm_recovered_and_outliers_down_weighted(seed: int) -> None:
    """The lever arm is within 4 of its marginal standard deviations (at the solution, with
    the final weights) of the truth on each axis; every injected outlier gets weight 0 from
    the χ² gate (they are 50-100 σ off), and at most 3 % of the good fixes do (the gate is
    the 99 % quantile). Without re-weighting the outliers pull the estimate away: its
    error exceeds the gated one."""
    ds, gps, out = _drive_with_gps(seed)
    res = fuse_gps(ds, gps, LandmarkGraphConfig(weighting=GpsWeighting("gate", 9.21)))
    fused = res.fused
    assert fused.lever_arm is not None and fused.weights is not None
    err = np.abs(fused.lever_arm - LEVER)
    # The marginal covariance of the lever arm at the solution and final weights.
    g = res.built.graph
    k = next(i for i, e in enumerate(g.edges) if e.kind == "gps")
    edges = list(g.edges)
    e = edges[k]
    edges[k] = reweight(e, e.information, fused.weights)
    graph = replace(g, edges=tuple(edges))
    lm = np.vstack([fused.landmarks, fused.lever_arm])
    at = optimize(graph, initial_poses=fused.poses, initial_landmarks=lm)
    marg = marginal_covariances(graph, at, landmark_ids=[res.built.lever_id])
    sd = np.sqrt(np.diag(marg.landmark_covariances[0]))
    assert np.all(err < 4 * sd), (err, sd)
    assert np.all(sd < 0.1)  # the bound is tight: the drive turns, the arm is observable
    in_graph = np.flatnonzero(res.built.fix_in_graph)
    w = np.full(gps.times.shape[0], np.nan)
    w[in_graph] = fused.weights
    assert np.all(w[out] == 0.0)
    good = np.setdiff1d(in_graph, out)
    assert np.mean(w[good] == 0.0) <= 0.03
    plain = fuse_gps(ds, gps, LandmarkGraphConfig(weighting=GpsWeighting("none")))
    assert plain.fused.lever_arm is not None
    assert np.linalg.norm(plain.fused.lever_arm - LEVER) > np.linalg.norm(err)
    # The fused path lies in the GPS frame: its antenna track matches the truth directly.
    truth_t, truth_p = ds.truth.times, ds.truth.poses
    assert truth_t is not None and truth_p is not None
    rows = np.searchsorted(truth_t, res.built.times)
    d = antenna_positions(fused.poses, LEVER) - antenna_positions(truth_p[rows], LEVER)
    assert np.sqrt(np.mean(np.sum(d**2, axis=1))) < 0.15  # measured 0.093 and 0.076 m


def test_readings_without_ids_are_refused() -> None:
    ds = build_landmark_clutter({}, seed=1)  # its readings come without ids
    with pytest.raises(InputError, match="without a landmark id"):
        build_landmark_graph(ds)


def test_gps_fixes_are_checked() -> None:
    t = np.arange(20.0)
    xy = np.zeros((20, 2))
    fixes = GpsFixes(t, xy, holdout_every=10)
    np.testing.assert_array_equal(np.flatnonzero(fixes.held_out), [9, 19])
    assert not GpsFixes(t, xy).held_out.any()
    with pytest.raises(InputError, match="increasing"):
        GpsFixes(t[::-1], xy)
    bad = xy.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        GpsFixes(t, bad)
    with pytest.raises(InputError, match="positions"):
        GpsFixes(t, xy[:5])
    with pytest.raises(ConfigError, match="sigma"):
        GpsFixes(t, xy, sigma=0.0)
    with pytest.raises(ConfigError, match="holdout_every"):
        GpsFixes(t, xy, holdout_every=1)


def test_fixes_with_their_own_covariances() -> None:
    """A fix's own covariance becomes its edge's information; a wrong shape or a matrix that
    is not positive definite is refused."""
    ds, gps, _ = _drive_with_gps(1)
    m = gps.times.shape[0]
    cov = np.tile(np.diag([0.09, 0.25]), (m, 1, 1))
    own = GpsFixes(gps.times, gps.positions, covariances=cov, holdout_every=10)
    built = build_landmark_graph(ds, gps=own)
    edges = next(e for e in built.graph.edges if e.kind == "gps")
    assert len(edges) == int(built.fix_in_graph.sum()) == m - m // 10
    np.testing.assert_allclose(
        edges.information, np.tile(np.diag([1 / 0.09, 1 / 0.25]), (len(edges), 1, 1))
    )
    with pytest.raises(InputError, match="covariances"):
        GpsFixes(gps.times, gps.positions, covariances=cov[:3])
    bad = cov.copy()
    bad[2] = np.diag([0.1, -0.1])
    with pytest.raises(InputError, match="covariances"):
        GpsFixes(gps.times, gps.positions, covariances=bad)


def test_fusion_needs_fixes_in_the_graph() -> None:
    """Fixes all before the drive (outside the controls' span): a one-line error, not a
    solve of a graph without its frame."""
    ds, gps, _ = _drive_with_gps(1)
    early = GpsFixes(gps.times - 1e4, gps.positions)
    with pytest.raises(InputError, match="fewer than two GPS fixes"):
        fuse_gps(ds, early)
