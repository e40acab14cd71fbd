"""Graph-based laser SLAM (``graph-slam``): keyframes, loop closures, the pose graph."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from slamkit.app import RunRequest, run_job
from slamkit.config import config_from_mapping
from slamkit.datasets import load_dataset
from slamkit.datasets.stream import LaserScan
from slamkit.errors import ConfigError, InputError
from slamkit.geometry.pose2 import between, interpolate_poses
from slamkit.io.posegraph import read_graph
from slamkit.models.constant_velocity import ConstantVelocity
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.slam.laser_graph import (
    NO_ODOMETRY,
    LaserGraphConfig,
    LaserGraphSlam,
    LoopMatch,
    LoopSettings,
    PoseGraph,
    SubmapCache,
    default_optimizer,
    edge_chi2,
    loop_candidates,
    loop_reference,
    search_window,
    submap,
    verify_closure,
)
from slamkit.slam.laser_graph.backend import MAX_CHI2, MAX_EDGE_CHI2, optimize_consistent
from slamkit.slam.laser_graph.frontend import (
    COAST_SEARCH,
    COAST_WINDOW_MAX_THETA,
    NORMAL_ICP,
    coast_window,
)
from slamkit.slam.laser_graph.loops import SUBMAP_KEYFRAMES, pair_consistent


@pytest.fixture(scope="module")
def loop_world():
    return load_dataset("corridor-loop-laser", seed=0)


@pytest.fixture(scope="module")
def slam(loop_world):
    """The estimator after the whole drive round the ring (its graph and keyframes)."""
    est = LaserGraphSlam(loop_world, LaserGraphConfig(), np.random.default_rng(0))
    for event in loop_world.events:
        est.handle(event)
    output = est.finish()
    truth = interpolate_poses(loop_world.truth.times, loop_world.truth.poses, est.keyframe_times)
    return est, output, truth


@pytest.fixture(scope="module")
def result(loop_world):
    return run("graph-slam", loop_world, seed=0)


def test_the_loop_is_closed_and_no_closure_is_false(slam) -> None:
    """Driving round the 100 m ring and on: about 20 closures where the robot re-enters the
    first corridor (measured 18), each within 10 cm and 1° of the true relative pose
    (measured at most 8.7 cm and 0.36°); every scan matched but a few (measured 640 of
    641)."""
    est, output, truth = slam
    closures = est.loop_closures()
    assert len(closures) >= 10
    i, j, z, _ = est.graph.edges()
    kinds = est.graph.edge_kinds()
    for e, kind in enumerate(kinds):
        if kind != "loop":
            continue
        err = between(z[e], between(truth[i[e]], truth[j[e]]))
        assert math.hypot(err[0], err[1]) < 0.1 and abs(math.degrees(err[2])) < 1.0
        # a closure ties the end of the drive to its start: a long way round in between
        assert est.keyframe_times[j[e]] - est.keyframe_times[i[e]] > 60.0
    d = output.diagnostics
    assert d["loops_kept"] == len(closures) and d["keyframes"] == len(est.graph)
    assert d["matched"] >= 0.95 * d["scans"]
    # Every solve starts from the running estimate, and each one converges.
    assert d["optimizations"] >= 1 and d["optimizations_not_converged"] == 0
    assert d["optimization_start"].startswith("the current estimate")
    assert output.grid is not None and output.graph is not None
    assert output.graph.poses.shape == (len(est.graph), 3)


def test_graph_slam_beats_dead_reckoning_and_scan_to_keyframe_odometry(loop_world, result) -> None:
    """ATE (SE(2)-aligned RMSE) on the ring, seed 0: dead reckoning 0.93 m, scan-to-keyframe
    laser odometry 0.26 m, graph SLAM 0.049 m (seeds 1, 2: 0.84 / 0.19 / 0.044 and
    1.56 / 0.33 / 0.052 m; with the keyframe reference 0.081 / 0.098 / 0.094 m).
    Laser odometry against its point map scores 0.067 m here: on a ring this small its
    20 m map reaches back to the first corridor, a closure of its own."""
    graph = evaluate(result, loop_world).scores.ate.rmse
    dead = evaluate(run("dead-reckoning", loop_world), loop_world).scores.ate.rmse
    keyframe = run("laser-odometry", loop_world, config={"reference": "keyframe"})
    lo = evaluate(keyframe, loop_world).scores.ate.rmse
    assert graph < 0.1
    assert graph < 0.15 * dead
    assert graph < 0.5 * lo


def test_the_long_hallway_is_closed_on_the_way_back() -> None:
    """The bare 50 m hallway there and back, seeds 0-2. Seed 0: dead reckoning 1.76 m ATE,
    laser odometry against the keyframe 1.12 m (52 scans degenerate along the hallway).
    Graph SLAM (the default front end: the local map with the wheels' offset as a prior,
    which holds the pose along the hallway): 0.392 / 0.109 / 0.089 m when this test was
    written, closures kept on each. A bare hallway is all aliases, and which side of an
    alias the back end takes swings one seed with any change (with the third session's
    defaults 0.088 / 0.403 / 0.231 m; seeds 0-5 in docs/estimators/laser_graph.md): the
    median over three seeds is what is held. (The keyframe reference bridges the degenerate
    stretch by the wheels alone: 1.94 m on seed 0.)"""
    ates = []
    for seed in range(3):
        data = load_dataset("long-hallway-laser", seed=seed)
        result = run("graph-slam", data, seed=0)
        d = result.output.diagnostics
        assert d["loops_kept"] >= 1 and sum(d["unmatched"].values()) <= 0.005 * d["scans"]
        ates.append(evaluate(result, data).scores.ate.rmse)
        if seed == 0:
            dead = evaluate(run("dead-reckoning", data), data).scores.ate.rmse
            keyframe = run("laser-odometry", data, config={"reference": "keyframe"})
            lo = evaluate(keyframe, data).scores.ate.rmse
    graph = float(np.median(ates))
    assert graph < 0.2
    assert graph < 0.25 * dead
    assert graph < 0.4 * lo


def test_the_runner_reports_the_optimised_path(slam, result, loop_world) -> None:
    """The recorded path is the final graph's (keyframe pose ⊕ offset at every stamp), the
    online estimates kept beside it; closing the loop moved the path, and for the better."""
    est, output, _ = slam
    assert result.online_poses is not None
    assert result.poses.shape == result.online_poses.shape
    at_keys = interpolate_poses(result.times, result.poses, est.keyframe_times)
    assert np.allclose(at_keys, output.graph.poses, atol=1e-9)
    moved = np.hypot(*(result.poses[:, :2] - result.online_poses[:, :2]).T)
    assert moved.max() > 0.05
    online = dataclasses.replace(result, poses=result.online_poses, online_poses=None)
    assert (
        evaluate(result, loop_world).scores.ate.rmse < evaluate(online, loop_world).scores.ate.rmse
    )


def test_a_wrong_candidate_is_refused_by_the_verification(slam) -> None:
    """The last keyframe's scan against a submap on the far side of the ring, presented as
    if it were taken there (identity initial guess): refused. The true candidate from the
    current estimate: accepted, within 10 cm of the truth, the bound every closure of the
    ring keeps (measured 7.8 cm; the submap is built at the estimated poses, so its own
    error is in the closure), and refused for its score when ``loops.min_score`` asks more
    than it reaches."""
    est, _, truth = slam
    settings = LoopSettings()
    poses = est.graph.poses
    points = [kf.points for kf in est.keyframes]
    k = len(poses) - 1
    far = int(np.argmax(np.hypot(*(truth[:k, :2] - truth[k, :2]).T)))
    assert np.hypot(*(truth[far, :2] - truth[k, :2])) > 15.0
    ref, cloud = submap(poses, points, far, 5)
    icp = NORMAL_ICP
    wrong = verify_closure(ref, cloud, points[k], np.zeros(3), (1.0, 0.3), settings, icp)
    assert isinstance(wrong, str)
    j, kk = est.loop_closures()[len(est.loop_closures()) // 2]
    ref, cloud = submap(poses, points, j, 5)
    right = verify_closure(
        ref, cloud, points[kk], between(poses[j], poses[kk]), (1.0, 0.3), settings, icp
    )
    assert isinstance(right, LoopMatch)
    err = between(right.pose, between(truth[j], truth[kk]))
    assert math.hypot(err[0], err[1]) < 0.1
    strict = LoopSettings(min_score=min(1.0, right.score + 0.05))
    refused = verify_closure(
        ref, cloud, points[kk], between(poses[j], poses[kk]), (1.0, 0.3), strict, icp
    )
    assert refused == "low_score"


def test_pairwise_consistency_refuses_a_closure_shifted_along_the_corridor(slam) -> None:
    """Two true closures agree (their cycle closes within the 10 cm / 1.5° tolerance); the
    same closure moved 0.5 m along the corridor does not."""
    est, _, truth = slam
    poses = est.graph.poses
    (j1, k1), (j2, k2) = est.loop_closures()[:2]
    z1, z2 = between(truth[j1], truth[k1]), between(truth[j2], truth[k2])
    assert pair_consistent(poses, (j2, k2, z2), (j1, k1, z1))
    shifted = z2 + np.array([0.5, 0.0, 0.0])
    assert not pair_consistent(poses, (j2, k2, shifted), (j1, k1, z1))


def _first_closure(est) -> tuple[tuple[int, int], np.ndarray]:
    """The ends and the information matrix of the first loop closure of ``est``'s graph."""
    i, j, _, info = est.graph.edges()
    first = next(e for e, kind in enumerate(est.graph.edge_kinds()) if kind == "loop")
    return (int(i[first]), int(j[first])), info[first]


def _solved_copy(est) -> PoseGraph:
    """A copy of ``est``'s final graph (poses and edges), optimised."""
    i, j, z, info = est.graph.edges()
    graph = PoseGraph(default_optimizer())
    for p in est.graph.poses:
        graph.add_pose(p)
    for e, kind in enumerate(est.graph.edge_kinds()):
        graph.add_edge(int(i[e]), int(j[e]), z[e], info[e], kind)
    graph.optimize()
    return graph


def test_the_backend_removes_an_injected_inconsistent_closure(slam) -> None:
    """A closure 1.5 m off the truth, weighted like the real ones, added to the final graph:
    the Δχ² check removes it and the poses stay where they were (within 1 cm); the true
    relative pose at the same weight is kept."""
    est, _, truth = slam
    (a, b), weight = _first_closure(est)
    for offset, removed in ((1.5, True), (0.0, False)):
        graph = _solved_copy(est)
        before = graph.poses
        wrong = between(truth[a], truth[b]) + np.array([offset, 0.0, 0.0])
        e = graph.add_edge(a, b, wrong, weight, "loop")
        out = optimize_consistent(graph, [e], MAX_CHI2)
        assert (out == [e]) is removed
        if removed:
            assert np.abs(graph.poses[:, :2] - before[:, :2]).max() < 0.01


@pytest.mark.parametrize(("offset", "count"), [(0.5, 2), (1.5, 2), (1.0, 3)])
def test_the_backend_removes_consistent_wrong_closures(slam, offset: float, count: int) -> None:
    """Two or three wrong closures that agree with each other (consecutive keyframes, all
    ``offset`` metres off the truth along x, as an aliased corridor gives them), weighted
    like the real ones and offered together: both are removed and the poses stay where
    they were (within 1 cm)."""
    est, _, truth = slam
    (a, b), weight = _first_closure(est)
    graph = _solved_copy(est)
    before = graph.poses
    shift = np.array([offset, 0.0, 0.0])
    pair = []
    for d in range(count):
        wrong = between(truth[a + d], truth[b + d]) + shift
        pair.append(graph.add_edge(a + d, b + d, wrong, weight, "loop"))
    out = optimize_consistent(graph, pair, MAX_CHI2, MAX_EDGE_CHI2)
    assert sorted(out) == pair
    assert np.abs(graph.poses[:, :2] - before[:, :2]).max() < 0.01


def test_the_tear_check_counts_the_change_of_an_edge_not_its_value() -> None:
    """``max_edge_chi2`` bounds how far the new closures move an earlier edge's residual
    (``Δeᵀ Ω Δe``). Two 1 m edges (1 cm, 1 mrad) already stretched to χ² ≈ 89 each by an
    accepted closure: a new closure bending them sideways to χ² ≈ 105 moves each by a
    few σ only and is kept (the rule of the value, "above 100 that was below it", refused
    it). Five closures agreeing with each other that stretch a fresh edge by more than
    10 σ between them are removed, although their total growth is within 100 each."""
    graph = PoseGraph(default_optimizer())
    for x in range(3):
        graph.add_pose([x, 0.0, 0.0])
    chain = np.diag([1e4, 1e4, 1e6])
    graph.add_edge(0, 1, [1.0, 0.0, 0.0], chain, "odometry")
    graph.add_edge(1, 2, [1.0, 0.0, 0.0], chain, "odometry")
    graph.add_edge(0, 2, [2.19, 0.0, 0.0], np.diag([1e6, 1e2, 1e2]), "loop")
    graph.optimize()
    strained = graph.chi2()[:2]
    new = graph.add_edge(0, 2, [2.19, 0.12, 0.0], np.diag([1e2, 1e4, 1e2]), "loop")
    assert optimize_consistent(graph, [new], 100.0, 100.0) == []
    after = graph.chi2()[:2]
    assert (strained > 80.0).all() and (strained < 100.0).all() and (after > 100.0).all()

    graph = PoseGraph(default_optimizer())
    graph.add_pose([0.0, 0.0, 0.0])
    graph.add_pose([1.0, 0.0, 0.0])
    graph.add_edge(0, 1, [1.0, 0.0, 0.0], np.eye(3) * 1e4, "odometry")
    closures = [graph.add_edge(0, 1, [1.16, 0.0, 0.0], np.eye(3) * 1e4, "loop") for _ in range(5)]
    assert sorted(optimize_consistent(graph, closures, 100.0, 100.0)) == closures
    assert graph.chi2() == pytest.approx([0.0], abs=1e-12)  # only the edge is left


def _circle_graph(rng: np.random.Generator) -> tuple[PoseGraph, np.ndarray]:
    """40 poses on a circle of 5 m (30 to a turn: 30-39 revisit 0-9), odometry edges of
    1 cm and 0.25° (noisy as much) and one loose edge, 15 → 16 (5 cm, 5°), that a wrong
    closure can bend; the truth."""
    a = 2.0 * np.pi * np.arange(40) / 30.0
    truth = np.stack([5.0 * np.cos(a), 5.0 * np.sin(a), a + np.pi / 2.0], axis=1)
    graph = PoseGraph(default_optimizer())
    for p in truth:
        graph.add_pose(p)
    for k in range(39):
        sd = np.array([0.05, 0.05, np.deg2rad(5.0)]) if k == 15 else np.array([0.01, 0.01, 0.0044])
        z = between(truth[k], truth[k + 1]) + sd * rng.standard_normal(3)
        graph.add_edge(k, k + 1, z, np.diag(1.0 / sd**2), "odometry")
    return graph, truth


def test_rejudge_reverses_an_early_wrong_closure_outnumbered_by_refused_ones() -> None:
    """Two wrong closures (31 → 1, 32 → 2, 1 m off) are in the graph, bending its loose
    edge; three true ones nearby were refused because of them. ``rejudge`` offers all five
    together: the wrong two are taken out, the true three kept, and the poses are those of
    the graph with the true three alone (within 1 mm). With two refused against two in the
    graph nothing changes."""
    from slamkit.slam.laser_graph.backend import RefusedClosure, rejudge

    closure = np.diag([1e4, 1e4, 1.0 / np.deg2rad(0.5) ** 2])
    for pool_size, reversed_ in ((3, True), (2, False)):
        graph, truth = _circle_graph(np.random.default_rng(0))
        for k in (31, 32):
            graph.add_edge(
                k,
                k - 30,
                between(truth[k], truth[k - 30]) + np.array([1.0, 0.0, 0.0]),
                closure,
                "loop",
            )
        graph.optimize()
        bent = graph.poses
        assert np.hypot(*(bent[31, :2] - truth[31, :2])) > 0.3
        pool = [
            RefusedClosure(k, k - 30, between(truth[k], truth[k - 30]), closure)
            for k in range(33, 33 + pool_size)
        ]
        out, readmitted, lost = rejudge(graph, pool, 20, 100.0, 100.0)
        if reversed_:
            assert (readmitted, lost) == (3, 2) and len(out) == 2
            assert {(c.i, c.j) for c in out} == {(31, 1), (32, 2)}
            assert sorted(graph.loop_pairs()) == [(33, 3), (34, 4), (35, 5)]
            right, _ = _circle_graph(np.random.default_rng(0))  # the true closures only
            for c in pool:
                right.add_edge(c.i, c.j, c.measurement, c.information, "loop")
            right.optimize()
            assert np.abs(graph.poses - right.poses).max() < 1e-3
        else:
            assert (readmitted, lost) == (0, 0) and out == pool
            assert np.array_equal(graph.poses, bent)


def test_the_whole_graph_check_retracts_an_early_wrong_pair_outvoted_later() -> None:
    """Two wrong closures (31 → 1, 32 → 2, 1 m off) entered the graph early, absorbed by
    its loose edge; three true ones (36 → 6 ... 38 → 8) came later. Judged with all of them
    in view, the wrong pair is retracted (its removal lowers the cost per closure most, far
    beyond χ²₃'s 99.9 % point), the true three stay, and the poses are those of the graph
    with the true three alone (within 1 mm)."""
    from slamkit.slam.laser_graph.backend import RETRACT_CHI2, closure_groups, retract_inconsistent

    closure = np.diag([1e4, 1e4, 1.0 / np.deg2rad(0.5) ** 2])
    graph, truth = _circle_graph(np.random.default_rng(0))
    right, _ = _circle_graph(np.random.default_rng(0))
    for k in (31, 32):
        wrong = between(truth[k], truth[k - 30]) + np.array([1.0, 0.0, 0.0])
        graph.add_edge(k, k - 30, wrong, closure, "loop")
    for k in (36, 37, 38):
        for g in (graph, right):
            g.add_edge(k, k - 30, between(truth[k], truth[k - 30]), closure, "loop")
    assert [len(group) for group in closure_groups(graph, 2)] == [2, 3]
    assert abs(RETRACT_CHI2 - 16.27) < 0.01
    assert sorted(retract_inconsistent(graph, 2)) == [(31, 1), (32, 2)]
    assert sorted(graph.loop_pairs()) == [(36, 6), (37, 7), (38, 8)]
    right.optimize()
    assert np.abs(graph.poses - right.poses).max() < 1e-3


@pytest.mark.parametrize("seed", range(3))
def test_refused_closures_are_offered_again_and_only_the_true_ones_come_back(seed: int) -> None:
    """The circle closed by one true closure (39 → 9); refused during the run: a wrong pair
    (31 → 1, 32 → 2, 1 m off) and a true pair (36 → 6, 37 → 7, as noisy as stated). Offered
    to the final graph, the true pair comes back (its Δ/n is χ²₃ below the bound), the
    wrong one does not (far beyond it), and the whole-graph check keeps what came back."""
    from slamkit.slam.laser_graph.backend import (
        RefusedClosure,
        restore_consistent,
        retract_inconsistent,
    )

    rng = np.random.default_rng(seed)
    sd = np.array([0.01, 0.01, np.deg2rad(0.5)])
    info = np.diag(1.0 / sd**2)
    graph, truth = _circle_graph(rng)
    graph.add_edge(39, 9, between(truth[39], truth[9]) + sd * rng.standard_normal(3), info, "loop")
    graph.optimize()
    wrong = [
        RefusedClosure(
            k, k - 30, between(truth[k], truth[k - 30]) + np.array([1.0, 0.0, 0.0]), info
        )
        for k in (31, 32)
    ]
    true = [
        RefusedClosure(
            k, k - 30, between(truth[k], truth[k - 30]) + sd * rng.standard_normal(3), info
        )
        for k in (36, 37)
    ]
    assert restore_consistent(graph, wrong + true, 2) == true
    assert retract_inconsistent(graph, 2) == []
    assert sorted(graph.loop_pairs()) == [(36, 6), (37, 7), (39, 9)]
    assert restore_consistent(graph, [], 2) == []


@pytest.mark.parametrize("seed", range(5))
def test_the_whole_graph_check_keeps_true_closures_with_noise_as_stated(seed: int) -> None:
    """The circle with ten true closures, each as noisy as its information says: nothing
    is retracted (the bound is the 99.9 % point, so this fails for a seed about once in a
    thousand groups; these seeds are not chosen)."""
    from slamkit.slam.laser_graph.backend import retract_inconsistent

    rng = np.random.default_rng(seed)
    sd = np.array([0.01, 0.01, np.deg2rad(0.5)])
    graph, truth = _circle_graph(rng)
    for k in range(30, 40):
        z = between(truth[k], truth[k - 30]) + sd * rng.standard_normal(3)
        graph.add_edge(k, k - 30, z, np.diag(1.0 / sd**2), "loop")
    assert retract_inconsistent(graph, 2) == []
    assert len(graph.loop_pairs()) == 10


def test_edge_chi2_and_the_search_region_by_hand() -> None:
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.1]])
    chi2 = edge_chi2(
        poses, np.array([0]), np.array([1]), np.array([[1.0, 0.0, 0.0]]), np.eye(3)[None] * 4.0
    )
    assert chi2 == pytest.approx([4.0 * 0.1**2])
    # The window starts at 0.5 m / 10° (loops.SEARCH_RADIUS, SEARCH_ANGLE_DEG).
    s = LoopSettings(radius_per_metre=0.02, max_radius=3.0)
    r, a = search_window(50.0, s)
    assert r == pytest.approx(1.5) and a == pytest.approx(math.radians(10.0 + 0.2 * 50))
    assert search_window(1000.0, s) == (3.0, pytest.approx(math.radians(30.0)))
    s = LoopSettings(angle_per_metre_deg=0.1, max_angle_deg=14.0)
    assert search_window(30.0, s)[1] == pytest.approx(math.radians(13.0))
    assert search_window(50.0, s)[1] == pytest.approx(math.radians(14.0))
    # keyframes 0..24 at x = 0.1 j with path lengths j (m); keyframe 25 at x = 2.4 after 40 m:
    # 24 is 0 m away (16 m of path), 19 is 0.5 m away (21 m), j is 40 - j m of path back.
    positions = np.array([[0.1 * j, 0.0] for j in range(25)] + [[2.4, 0.0]])
    travelled = np.array([*range(25), 40.0])
    s = LoopSettings(min_travel=6.0, radius_per_metre=0.0)
    assert loop_candidates(positions, travelled, 25, s) == [24]  # 19-23 too near in index
    s = LoopSettings(min_travel=20.0, radius_per_metre=0.0)
    assert loop_candidates(positions, travelled, 25, s) == [20]  # 21-24: too little travel
    # Grown by 0.1 m per metre, the radius at 13 (27 m back) is 3.2 m: 13 is 1.1 m away and 11
    # keyframes from 24 (loops.SUBMAP_KEYFRAMES); two at most (loops.MAX_CANDIDATES).
    s = LoopSettings(min_travel=6.0, radius_per_metre=0.1)
    assert loop_candidates(positions, travelled, 25, s) == [24, 13]
    s = LoopSettings(min_travel=6.0, radius_per_metre=0.1, max_radius=1.0)
    assert loop_candidates(positions, travelled, 25, s) == [24]


def test_settings_are_checked_and_a_laser_is_required(loop_world) -> None:
    with pytest.raises(ConfigError, match="keyframe_distance"):
        config_from_mapping(LaserGraphConfig, {"frontend": {"keyframe_distance": -1.0}})
    cfg = config_from_mapping(LaserGraphConfig, {"loops": {"min_score": 0.7}})
    assert cfg.loops.min_score == 0.7
    with pytest.raises(InputError, match="laser"):
        LaserGraphSlam(dataclasses.replace(loop_world, laser=None, events=()), cfg, None)


def test_run_job_writes_the_graph_as_g2o(tmp_path) -> None:
    report = run_job(
        RunRequest("graph-slam", "rooms-laser", tmp_path / "run", plots=False, preset=None)
    )
    assert "graph.g2o" in report.files and "trajectory.tum" in report.files
    assert {"map.pgm", "map.yaml"} <= set(report.files)
    from slamkit.io.rosmap import read_ros_map

    grid = read_ros_map(tmp_path / "run" / "map.yaml")
    built = report.result.output.grid
    assert grid.shape == built.shape and np.allclose(grid.origin_xy, built.origin_xy)
    graph = read_graph(tmp_path / "run" / "graph.g2o")
    out = report.result.output.graph
    assert graph.poses.shape == out.poses.shape
    assert np.allclose(graph.poses, out.poses, atol=1e-5)
    assert graph.n_edges == out.n_edges


@pytest.mark.realdata
@pytest.mark.slow
def test_aces_first_600_s_relations(raw_log) -> None:
    """The first 600 s of the raw ACES log (405 keyframes): measured 0.034 ± 0.029 m and
    0.35 ± 0.33° over the 533 relations it covers (with the keyframe reference 0.034 ±
    0.029 m, 0.34°; published graph mapping over the whole log: 0.044 m). ACES's raw
    odometry is good over the short relations of this window (0.031 m) but turns worse:
    0.87° against 0.36°."""
    from slamkit.eval.relations import relation_errors

    data = raw_log("aces-raw", 600.0)
    result = run("graph-slam", data, seed=0)
    rel = relation_errors(result.times, result.poses, data.truth.relations)
    assert rel.count >= 500
    assert rel.translation_mean < 0.045 and rel.rotation_mean_deg < 0.5
    odometry = run("dead-reckoning", data, seed=0)
    odo = relation_errors(odometry.times, odometry.poses, data.truth.relations)
    assert rel.rotation_mean_deg < 0.5 * odo.rotation_mean_deg


@pytest.mark.realdata
def test_freiburg_079_is_scored_in_the_logs_robot_frame(raw_log) -> None:
    """The first 300 s of raw Freiburg 079 (345 relations): with the registered mounting
    (the laser 4 cm behind the centre, the original log's robot_frontlaser_offset) measured
    0.0256 ± 0.017 m; with the bag's /tf_static (4 cm ahead) 0.0378 ± 0.038 m, 1.48× worse
    — the benchmark's relations are in the log's robot frame (docs/relations.md)."""
    from slamkit.eval.relations import relation_errors

    data = raw_log("fr079-raw", 300.0)
    assert data.laser.mounting == (-0.04, 0.0, 0.0)
    scores = []
    for config in ({}, {"mounting": (0.04, 0.0, 0.0)}):
        result = run("graph-slam", data, seed=0, config=config)
        rel = relation_errors(result.times, result.poses, data.truth.relations)
        assert rel.count >= 340
        scores.append(rel.translation_mean)
    assert scores[0] < 0.03
    assert scores[1] > 1.3 * scores[0]


def _without_odometry(data):
    """The data set as a laser-only log: no motion model, the scans alone."""
    scans = tuple(e for e in data.events if isinstance(e, LaserScan))
    return dataclasses.replace(data, motion=None, events=scans)


def test_a_log_without_odometry_runs_on_scan_matching_alone_and_says_so() -> None:
    """rooms-laser without its odometry: every scan but one matched (the constant-velocity
    prediction placed by a correlative search, refined by point-to-line ICP), 52 closures,
    ATE 1.29 m (seed 0; 0.89 m before the no-odometry rules of 2026-12-07; seeds 1-3 2.25,
    2.26, 1.33 m since the free-space check) — against 0.026 m with the wheels: along the
    rooms' corridor the scans hold the motion too loosely for matching alone, which the
    wheels' prior fixes. The default front end is then the keyframe's (``reference =
    "auto"``); the local map with only the coasted prediction as its prior scores 0.90,
    0.75, 3.03, 2.86 m on seeds 0-3 (docs/estimators/laser_graph.md)."""
    data = load_dataset("rooms-laser", seed=0)
    result = run("graph-slam", _without_odometry(data), seed=0)
    d = result.output.diagnostics
    assert d["odometry"] == NO_ODOMETRY and d["frontend_reference"] == "keyframe"
    assert d["matched"] >= 0.99 * d["scans"] and d["loops_kept"] >= 20
    ate = evaluate(result, data).scores.ate.rmse
    assert ate < 1.5
    on_map = run("graph-slam", _without_odometry(data), config={"frontend": {"reference": "map"}})
    assert on_map.output.diagnostics["frontend_reference"] == "map"
    with pytest.raises(InputError, match="needs motion"):
        run("grid-rbpf", _without_odometry(data), seed=0)


def test_a_generated_building_without_odometry_is_mapped() -> None:
    """Generated building 11 (the shortest route of the corpus) by scan matching alone.
    Before the turn rate was dropped after a failed match, the search window widened with the
    interval and degenerate matches fused with the prediction, the held turn rate spun the
    prediction out of the search window after the first turns and the run scored 10.1 m ATE
    (now 0.62 m)."""
    from slamkit.sim.buildings import build_building_dataset

    data = build_building_dataset(11)
    result = run("graph-slam", _without_odometry(data), seed=0)
    d = result.output.diagnostics
    assert d["odometry"] == NO_ODOMETRY
    assert d["matched"] >= 0.99 * d["scans"]
    # Measured: 704 of 705 scans matched, 39 of them fused with the prediction along a
    # corridor, 6 matched speeds not believed.
    assert d["degenerate_fused"] >= 20 and d["speed_not_believed"] >= 1
    assert evaluate(result, data).scores.ate.rmse < 1.2


def test_the_held_velocity_drops_its_turn_and_disbelieves_a_jump_in_speed() -> None:
    """A failed match keeps the translation and drops the turn rate; a degenerate match's
    turn alone is observed; a speed beyond GATE σ_xy T of the held one (T: the time since
    the translation was last observed) is not taken, its turn is; the correlative window's
    heading half-width is two standard deviations of the prediction over the interval,
    within COAST_SEARCH's and the cap."""
    cv = ConstantVelocity()
    assert cv.observe(np.array([0.3, 0.0, math.radians(20.0)]), 0.5)
    np.testing.assert_allclose(cv.velocity, [0.6, 0.0, math.radians(40.0)])
    cv.lose_turn(0.5)
    np.testing.assert_allclose(cv.velocity, [0.6, 0.0, 0.0])
    cv.observe_turn(math.radians(10.0), 0.5)
    np.testing.assert_allclose(cv.velocity, [0.6, 0.0, math.radians(20.0)])
    # 1.5 s unobserved: the gate is 3 · 0.5 · 1.5 = 2.25 m/s; 3 m/s is 2.4 m/s away.
    assert not cv.observe(np.array([1.5, 0.0, math.radians(5.0)]), 0.5)
    np.testing.assert_allclose(cv.velocity, [0.6, 0.0, math.radians(10.0)])
    assert cv.unobserved == pytest.approx(1.5)
    # Half a second later the gate is 3 · 0.5 · 2.5 = 3.75 m/s: the same speed is taken.
    assert cv.observe(np.array([1.5, 0.0, 0.0]), 0.5)
    np.testing.assert_allclose(cv.velocity, [3.0, 0.0, 0.0])
    assert cv.unobserved == 0.0
    assert coast_window(cv.predict(0.1)[1]).window_theta == COAST_SEARCH.window_theta
    wide = coast_window(cv.predict(0.5)[1])
    assert wide.window_theta == pytest.approx(math.radians(2.0 * 45.0 * 0.5))
    assert wide.window_xy == COAST_SEARCH.window_xy
    assert coast_window(cv.predict(5.0)[1]).window_theta == COAST_WINDOW_MAX_THETA


@pytest.mark.realdata
@pytest.mark.slow
def test_aces_without_odometry_first_300_s(raw_log) -> None:
    """The first 300 s of raw ACES by scan matching alone: measured 0.042 ± 0.045 m, 0.32°
    over 291 relations (0.048 ± 0.071 m, 0.34° before the no-odometry rules of 2026-12-07;
    with the wheels: 0.037 ± 0.034 m, 0.30°)."""
    from slamkit.eval.relations import relation_errors

    data = raw_log("aces-raw", 300.0)
    result = run("graph-slam", _without_odometry(data), seed=0)
    rel = relation_errors(result.times, result.poses, data.truth.relations)
    assert rel.count >= 280
    assert rel.translation_mean < 0.06 and rel.rotation_mean_deg < 0.45


def test_a_smoothed_trajectory_is_checked() -> None:
    from slamkit.errors import NonFiniteError, ShapeError
    from slamkit.estimation import SmoothedTrajectory

    ok = SmoothedTrajectory(np.array([0.0, 1.0]), np.zeros((2, 3)))
    assert ok.poses.shape == (2, 3)
    with pytest.raises(ShapeError, match="poses"):
        SmoothedTrajectory(np.array([0.0, 1.0]), np.zeros((3, 3)))
    with pytest.raises(InputError, match="increase"):
        SmoothedTrajectory(np.array([1.0, 0.0]), np.zeros((2, 3)))
    with pytest.raises(NonFiniteError):
        SmoothedTrajectory(np.array([0.0, 1.0]), np.full((2, 3), np.nan))


def test_pose_graph_grows_past_its_capacity_and_removes_edges() -> None:
    rng = np.random.default_rng(5)
    graph = PoseGraph(default_optimizer())
    poses = rng.normal(size=(40, 3))
    assert [graph.add_pose(p) for p in poses] == list(range(40))
    kinds = ["odometry", "loop", "odometry"]
    edges = [
        (int(a), int(a) + 1, rng.normal(size=3), np.eye(3) * (a + 1), kinds[a % 3])
        for a in range(39)
    ]
    for e in edges:
        graph.add_edge(*e)
    np.testing.assert_array_equal(graph.poses, poses)
    np.testing.assert_array_equal(graph.pose(7), poses[7])
    graph.pose(7)[0] = 99.0  # a copy: the graph keeps its estimate
    assert graph.poses[7, 0] == poses[7, 0]
    graph.remove_edges([0, 5, 38])
    kept = [e for n, e in enumerate(edges) if n not in (0, 5, 38)]
    i, j, z, info = graph.edges()
    assert i.tolist() == [e[0] for e in kept] and j.tolist() == [e[1] for e in kept]
    np.testing.assert_array_equal(z, [e[2] for e in kept])
    np.testing.assert_array_equal(info, [e[3] for e in kept])
    assert graph.edge_kinds() == [e[4] for e in kept]
    assert graph.loop_pairs() == [(e[0], e[1]) for e in kept if e[4] == "loop"]


def test_submap_cache_reuses_a_submap_only_while_its_poses_stay(slam) -> None:
    est, _, _ = slam
    settings = LoopSettings()
    poses = est.graph.poses
    points = [kf.points for kf in est.keyframes]
    j = len(poses) // 2
    cache = SubmapCache(settings)
    ref, cloud, reference = cache.get(poses, points, j)
    fresh, fresh_cloud = submap(poses, points, j, SUBMAP_KEYFRAMES // 2)
    np.testing.assert_array_equal(ref, fresh)
    np.testing.assert_array_equal(cloud.points, fresh_cloud.points)
    np.testing.assert_array_equal(
        reference.lookup.tables[0], loop_reference(fresh, settings).lookup.tables[0]
    )
    cache.advance()
    assert cache.get(poses, points, j)[2] is reference  # nothing moved: the same
    moved = poses.copy()
    moved[j + 1, 0] += 1e-9
    cache.advance()
    assert cache.get(moved, points, j)[2] is not reference  # a pose moved: rebuilt
    cache.advance()
    cache.advance()  # not asked for at the last keyframe: forgotten
    assert cache.get(moved, points, j)[2] is not reference


@pytest.mark.parametrize(
    ("section", "name"),
    [("frontend", "fuse_degenerate"), ("frontend", "neighbour_edges"), ("loops", "closure_travel")],
)
def test_settings_deleted_for_losing_on_real_logs_are_named_in_the_error(section, name) -> None:
    with pytest.raises(ConfigError, match=rf"{name} \(graph SLAM: removed 2026-12-07"):
        config_from_mapping(LaserGraphConfig, {section: {name: 1}}, "graph-slam")


def test_without_loop_closure_the_ring_stays_open(loop_world, result) -> None:
    """``loops.enabled = False``: no candidate searched, no closure, and the ring's ATE is the
    front end's drift (measured 0.174 m on seed 0, against 0.048 m with closures; seeds 1
    and 2: 0.082 / 0.046 m and 0.056 / 0.054 m); the map is built at ``map_resolution``."""
    config = {"loops": {"enabled": False}, "map_resolution": 0.1}
    chain = run("graph-slam", loop_world, seed=0, config=config)
    d = chain.output.diagnostics
    assert d["loop_candidates"] == 0 and d["loops_kept"] == 0
    ate = evaluate(chain, loop_world).scores.ate.rmse
    assert ate > 2.0 * evaluate(result, loop_world).scores.ate.rmse
    assert chain.output.grid.resolution == 0.1 and result.output.grid.resolution == 0.05
