"""The grid RBPF says when it lost a loop (:mod:`slamkit.slam.grid_rbpf.loops`): its best
particle's map holding the revisited place twice is found by a wide search of the scan on
the old map, and reported; a run that closes its loops is not."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamkit.datasets import load_dataset
from slamkit.datasets.stream import Dataset, LaserScan
from slamkit.models.laser import scan_points
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.sim.odometry_errors import OdometryErrorModel, corrupt_odometry
from slamkit.slam.grid_rbpf.loops import MIN_OFFSET, OLD_AFTER, LoopWatch, particle_spread

NO_GLITCHES = {
    "heading_jump_rate": 0.0,
    "stall_rate": 0.0,
    "duplicate_rate": 0.0,
    "out_of_order_rate": 0.0,
}


def _ring(max_range: float, wheels: dict[str, float]) -> Dataset:
    """The ring of corridors driven twice round (``corridor-loop-laser``, seed 0) with the
    laser's range cut to ``max_range`` and the wheels' errors ``wheels`` (no glitches)."""
    data = load_dataset("corridor-loop-laser", seed=0, options={"laps": 2, "max_range": max_range})
    model = OdometryErrorModel(**NO_GLITCHES, **wheels)
    out, _ = corrupt_odometry(data, model, np.random.default_rng(0))
    return out


def test_a_lost_loop_is_said() -> None:
    """Two particles, a 4 m laser and wheels 8 % off in radius and base: the drift round the
    100 m ring reaches 2 m, beyond the proposal's reach, and the first lap's corridor is
    mapped again beside itself. Measured: the place found doubled at 119.6 s, 2.2 m from the
    filter's pose (the true error of the filter's pose against its old scans there: 2.1 m),
    and again at 144.2 s, 1.6 m (true: 1.6 m): the loop is lost there."""
    data = _ring(4.0, {"wheel_radius_error": 0.08, "wheel_base_error": 0.08, "k_drift": 0.05})
    result = run("grid-rbpf", data, seed=0, config={"particles": 2})
    d = result.output.diagnostics
    kinds = [w.kind for w in result.output.warnings]
    assert "loop_lost" in kinds
    assert d["loops_lost"] >= 1 and d["loop_checks"] >= 5
    first = d["loop_lost_at"][0]
    assert 1.2 < first["offset_m"] < 3.0
    assert 100.0 < first["t"] < 160.0  # at the first revisit, after one lap (~100 m)


def test_a_closed_loop_is_not_said() -> None:
    """The same ring with its 12 m laser and the typical wheels (1 % off): five particles
    close both laps (measured: ATE 0.32 m, 15 checks; ten particles 0.16 m, every check
    within 0.1 m of the filter's pose), and no warning is raised."""
    data = _ring(12.0, {"wheel_radius_error": 0.01, "wheel_base_error": 0.01})
    result = run("grid-rbpf", data, seed=0, config={"particles": 5})
    d = result.output.diagnostics
    ate = evaluate(result, data).scores.ate
    assert hasattr(ate, "rmse") and ate.rmse < 0.5
    assert d["loop_checks"] >= 8 and d["loops_lost"] == 0
    assert "loop_lost" not in [w.kind for w in result.output.warnings]


def _ring_scans() -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """The true poses ``(U, 3)``, end points (robot frame) and travel [m] of the clean ring
    drive's scans, one every 0.5 m of travel (as the filter's updates are)."""
    data = load_dataset("corridor-loop-laser", seed=0, options={"laps": 2})
    assert data.truth.poses is not None and data.laser is not None
    scans = [e for e in data.events if isinstance(e, LaserScan)]
    poses = data.truth.poses
    step = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    travel = np.concatenate([[0.0], np.cumsum(step)])
    keep = np.flatnonzero(np.diff(np.floor(travel / 0.5), prepend=-1.0) > 0)
    angles = data.laser.beam_angles
    points = [scan_points(scans[k].ranges, angles, data.laser.max_range) for k in keep]
    return poses[keep], points, travel[keep]


@pytest.mark.parametrize("shift", [(0.0, 0.0), (1.5, 0.6)])
def test_the_watch_measures_the_map_against_itself(shift: tuple[float, float]) -> None:
    """The watch fed a path whose second lap is moved by ``shift`` (a loop lost by that
    much: the old scans sit where they were mapped, the new ones beside them) finds the
    scan on the old map ``shift`` away from the filter's pose, to a cell (10 cm), at every
    check of the second lap, calls the place doubled and, from the second check on, the
    loop lost; the true path is found where it is."""
    poses, points, travel = _ring_scans()
    path = poses.copy()
    second = travel > 105.0  # the first lap is ~100 m
    path[second, :2] += shift
    watch = LoopWatch()
    first_new = float(np.argmax(second))  # stamps are update indices here
    found = []
    for u in range(path.shape[0]):
        watch.add(points[u], float(travel[u]))
        if watch.due():
            check = watch.check(float(u), path[: u + 1], 0.02)
            if check is not None and second[u]:
                found.append(check)
    size = math.hypot(*shift)
    assert len(found) >= 8
    for check in found:
        assert abs(check.offset - size) <= 0.15
    # Until the second lap's own scans are old too (30 m later), the old map holds the
    # place once, and the match is clear; after, it holds both copies (a rival).
    clear = [c for c in found if c.old_scans and c.t < first_new + OLD_AFTER / 0.5]
    assert len(clear) >= 4
    assert all(c.doubled == (size > MIN_OFFSET) for c in clear)
    assert [c.lost for c in clear] == [False] + [size > MIN_OFFSET] * (len(clear) - 1)
    lost = watch.warnings()
    assert [w.kind for w in lost] == (["loop_lost"] if size else [])


def test_particle_spread_by_hand() -> None:
    """sqrt(tr Σ_xy) of the weighted positions: two particles 2 m apart, equal weights, 1 m;
    weights 0.9 / 0.1, sqrt(0.9·0.2² + 0.1·1.8²) = 0.6 m; headings do not count."""
    poses = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 3.0]])
    assert particle_spread(poses, np.array([0.5, 0.5])) == pytest.approx(1.0)
    assert particle_spread(poses, np.array([0.9, 0.1])) == pytest.approx(0.6)
