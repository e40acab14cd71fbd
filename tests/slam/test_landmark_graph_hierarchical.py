"""The hierarchical GPS fusion (:mod:`slamkit.slam.landmark_graph.hierarchical`) on a simulated
drive with known truth: the anchored factor's Jacobians, its identity with the flat graph when
every submap is one odometry step, the rigid single map, accuracy against the flat solution
and the truth, and outliers still rejected."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from slamkit.errors import ConfigError, InputError
from slamkit.geometry import pose2
from slamkit.optim import OptimizerConfig
from slamkit.optim.data import EdgeSet
from slamkit.optim.factors import retract_poses
from slamkit.optim.gps import anchored_gps_error
from slamkit.optim.settings import StoppingConfig
from slamkit.sim.scenarios import build_landmark_loop
from slamkit.slam.landmark_graph import (
    GpsFixes,
    LandmarkGraph,
    LandmarkGraphConfig,
    antenna_positions,
    build_landmark_graph,
    fuse_gps,
    solve_fused,
    solve_hierarchical,
    solve_unfused,
)

LEVER = np.array([1.5, -0.4])  # the true antenna position in the robot frame [m]
SIGMA = 0.3  # GPS noise per axis [m]
N_OUT = 8  # outliers: fixes moved 15-30 m
TIGHT = LandmarkGraphConfig(
    optimizer=OptimizerConfig(
        stopping=StoppingConfig(relative_tolerance=1e-14, absolute_tolerance=1e-14)
    )
)


def _drive(seed: int, duration: float = np.inf) -> tuple[object, GpsFixes, np.ndarray]:
    """The simulated loop with a fix every fifth step at the lever arm, N_OUT of them moved
    15-30 m (the same construction as ``test_landmark_graph_gps``); the events of the first
    ``duration`` seconds only."""
    rng = np.random.default_rng(seed)
    ds = build_landmark_loop({}, seed=seed)
    ds = replace(ds, events=[e for e in ds.events if e.t <= duration])
    times, poses = ds.truth.times, ds.truth.poses
    assert times is not None and poses is not None
    take = np.arange(1, times.shape[0], 5)
    t = times[take]
    xy = antenna_positions(poses[take], LEVER) + rng.normal(0.0, SIGMA, (t.shape[0], 2))
    out = rng.choice(t.shape[0], N_OUT, replace=False)
    ang = rng.uniform(0, 2 * np.pi, N_OUT)
    xy[out] += rng.uniform(15.0, 30.0, N_OUT)[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1)
    return ds, GpsFixes(t, xy, sigma=SIGMA), out


def _antenna_rmse(built: LandmarkGraph, ds: object, poses: np.ndarray) -> float:
    truth_t, truth_p = ds.truth.times, ds.truth.poses  # type: ignore[attr-defined]
    rows = np.searchsorted(truth_t, built.times)
    d = antenna_positions(poses, LEVER) - antenna_positions(truth_p[rows], LEVER)
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def test_anchored_gps_jacobians_against_finite_differences() -> None:
    """``∂e/∂δ_B`` (right update of the base) and ``∂e/∂o`` by central differences; the
    error itself is the plain GPS error of the composed pose ``B ∘ Y``."""
    rng = np.random.default_rng(3)
    base = np.column_stack([rng.normal(0, 20, 5), rng.normal(0, 20, 5), rng.uniform(-3, 3, 5)])
    local = np.column_stack([rng.normal(0, 5, 5), rng.normal(0, 5, 5), rng.uniform(-3, 3, 5)])
    lever = np.tile(rng.normal(0, 2, 2), (5, 1))
    z = rng.normal(0, 20, (5, 2))
    e, Jb, Jo = anchored_gps_error(base, local, lever, z)
    w = pose2.compose(base, local)
    c, s = np.cos(w[:, 2]), np.sin(w[:, 2])
    direct = w[:, :2] + np.column_stack(
        [c * lever[:, 0] - s * lever[:, 1], s * lever[:, 0] + c * lever[:, 1]]
    ) - z  # fmt: skip
    np.testing.assert_allclose(e, direct, atol=1e-12)
    h = 1e-6
    for a in range(3):
        d = np.zeros((5, 3))
        d[:, a] = h
        ep, _, _ = anchored_gps_error(retract_poses(base, d), local, lever, z)
        em, _, _ = anchored_gps_error(retract_poses(base, -d), local, lever, z)
        np.testing.assert_allclose((ep - em) / (2 * h), Jb[:, :, a], atol=1e-6)
    for a in range(2):
        d = np.zeros((5, 2))
        d[:, a] = h
        ep, _, _ = anchored_gps_error(base, local, lever + d, z)
        em, _, _ = anchored_gps_error(base, local, lever - d, z)
        np.testing.assert_allclose((ep - em) / (2 * h), Jo[:, :, a], atol=1e-6)


def _without_readings(built: LandmarkGraph) -> LandmarkGraph:
    g = built.graph
    keep = g.landmark_ids == built.lever_id
    graph = replace(
        g,
        edges=tuple(e for e in g.edges if e.kind != "range_bearing"),
        landmark_ids=g.landmark_ids[keep],
        landmarks=g.landmarks[keep],
    )
    return replace(built, graph=graph, initial_landmarks=g.landmarks[keep])


def _final_readings_dropped(built: LandmarkGraph) -> LandmarkGraph:
    """``built`` without the readings of its final node (the one node no submap is based at)."""
    n = built.times.shape[0]
    edges = []
    for e in built.graph.edges:
        if e.kind == "range_bearing":
            k = e.i != n - 1
            e = EdgeSet(e.kind, e.i[k], e.j[k], e.measurement[k], e.information[k], e.lines[k])
        edges.append(e)
    return replace(built, graph=replace(built.graph, edges=tuple(edges)))


def test_one_step_submaps_equal_the_flat_graph_without_readings() -> None:
    """With ``P = 1`` a submap is one odometry edge and readings of its base alone: its end's
    marginal is the edge's covariance, its landmarks tie nothing, so the top level is the flat
    fused graph without readings. Both solved tight, with the gate (the outliers set aside by
    both): the same poses (1e-6 m), lever arm and weights."""
    ds, gps, _ = _drive(1, duration=50.0)
    built = _final_readings_dropped(build_landmark_graph(ds, gps=gps))
    hier = solve_hierarchical(built, 1, TIGHT)
    h = hier.solution
    assert hier.submaps == built.times.shape[0] - 1
    assert h.lever_arm is not None and h.weights is not None
    flat = solve_fused(_without_readings(built), h.poses, h.lever_arm[None, :], TIGHT)
    assert flat.lever_arm is not None and flat.weights is not None
    assert h.converged and flat.converged
    np.testing.assert_array_equal(flat.weights, h.weights)
    np.testing.assert_allclose(h.poses[:, :2], flat.poses[:, :2], atol=1e-6)
    np.testing.assert_allclose(h.poses[:, 2], flat.poses[:, 2], atol=1e-7)
    np.testing.assert_allclose(h.lever_arm, flat.lever_arm, atol=1e-6)


def test_one_submap_is_the_unfused_map_moved_rigidly() -> None:
    """With one submap the map is the graph without GPS, placed as a whole: every relative
    pose equals the unfused solution's (1e-5), and it cannot bend to the fixes, so its path
    is farther from the truth than the flat fused one."""
    ds, gps, _ = _drive(1)
    res = fuse_gps(ds, gps)
    built = res.built
    hier = solve_hierarchical(built, 10**9)
    assert hier.submaps == 1 and hier.top_variables == 8
    h = hier.solution
    unfused = solve_unfused(built)
    rel_h = pose2.between(h.poses[0], h.poses)
    rel_u = pose2.between(unfused.poses[0], unfused.poses)
    np.testing.assert_allclose(rel_h, rel_u, atol=1e-5)
    assert _antenna_rmse(built, ds, h.poses) > 2 * _antenna_rmse(built, ds, res.fused.poses)


@pytest.mark.parametrize("seed", [1, 2])
def test_submaps_close_to_flat_and_truth_outliers_rejected(seed: int) -> None:
    """Submaps of 50 poses (24 of them): the antenna track within 0.2 m RMS of the truth
    (measured 0.12 and 0.10 m; the flat graph 0.09 and 0.08 m) and 0.15 m of the flat fused
    path (0.065, 0.092 m); the lever arm within 0.15 m of the truth on each axis (errors
    0.04 m at most); every injected outlier gets weight 0 and at most 3 % of the good fixes
    do; the trees within 0.15 m RMS of the flat map (0.064, 0.082 m)."""
    ds, gps, out = _drive(seed)
    res = fuse_gps(ds, gps)
    built = res.built
    calls: list[tuple[int, int]] = []
    hier = solve_hierarchical(built, 50, progress=lambda k, n: calls.append((k, n)))
    h = hier.solution
    assert calls == [(k, 24) for k in range(1, 25)]
    assert hier.submaps == 24 and hier.top_variables == 3 * 25 + 2
    assert hier.largest_local < hier.flat_variables / 10
    assert h.converged and h.lever_arm is not None and h.weights is not None
    assert _antenna_rmse(built, ds, h.poses) < 0.2
    d = h.poses[:, :2] - res.fused.poses[:, :2]
    assert np.sqrt(np.mean(np.sum(d**2, axis=1))) < 0.15
    assert np.all(np.abs(h.lever_arm - LEVER) < 0.15)
    w = np.full(gps.times.shape[0], np.nan)
    w[np.flatnonzero(built.fix_in_graph)] = h.weights
    assert np.all(w[out] == 0.0)
    good = np.setdiff1d(np.flatnonzero(built.fix_in_graph), out)
    assert np.mean(w[good] == 0.0) <= 0.03
    np.testing.assert_array_equal(h.landmark_ids, res.fused.landmark_ids)
    lm_err = np.linalg.norm(h.landmarks - res.fused.landmarks, axis=1)
    assert np.sqrt(np.mean(lm_err**2)) < 0.15


def test_bad_requests_are_refused() -> None:
    ds, gps, _ = _drive(1, duration=20.0)
    built = build_landmark_graph(ds, gps=gps)
    with pytest.raises(ConfigError, match="submap_poses"):
        solve_hierarchical(built, 0)
    with pytest.raises(InputError, match="fewer than two GPS fixes"):
        solve_hierarchical(build_landmark_graph(ds), 10)
