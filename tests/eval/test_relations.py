"""The relation metric (Kümmerle et al. 2009): hand-computed errors, frame invariance,
interpolation and coverage, the run scores, and the benchmark's files."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from slamkit.datasets import Relations, load_dataset, read_relations
from slamkit.errors import InputError, ShapeError
from slamkit.eval import (
    RelationError,
    poses_at_stamps,
    relation_errors,
    select_relations,
)
from slamkit.eval.records import Skipped
from slamkit.geometry.pose2 import between, compose
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate

D = math.radians


def hand_case() -> tuple[np.ndarray, np.ndarray, Relations]:
    """Four poses driven in the robot frame from a start facing +y, and four relations: one
    exact, one 0.1 m off sideways, one 2° off, one 0.5 m and 1° off over the whole path."""
    x0 = np.array([1.0, 2.0, np.pi / 2])
    x1 = compose(x0, [1.0, 0.0, 0.0])  # (1, 3, π/2)
    x2 = compose(x1, [1.0, 0.0, np.pi / 2])  # (1, 4, π)
    x3 = compose(x2, [0.5, 0.0, 0.0])  # (0.5, 4, π)
    poses = np.stack([x0, x1, x2, x3])
    times = np.array([10.0, 11.0, 12.0, 13.0])
    deltas = np.array(
        [
            [1.0, 0.0, 0.0],  # exact
            [1.0, 0.1, np.pi / 2],  # estimated (1, 0, π/2): 0.1 m
            [0.5, 0.0, D(2.0)],  # estimated (0.5, 0, 0): 2°
            [2.0 + 0.3, 0.5 - 0.4, np.pi / 2 + D(1.0)],  # estimated (2, 0.5, π/2): 0.5 m, 1°
        ]
    )
    rel = Relations(np.array([10.0, 11.0, 12.0, 10.0]), np.array([11.0, 12.0, 13.0, 13.0]), deltas)
    return times, poses, rel


def test_hand_computed_errors_and_statistics():
    times, poses, rel = hand_case()
    # The fourth relation is in the robot frame at t1: the world displacement (-0.5, 2)
    # seen from a robot facing +y is (2, 0.5).
    np.testing.assert_allclose(between(poses[0], poses[3]), [2.0, 0.5, np.pi / 2], atol=1e-15)
    r = relation_errors(times, poses, rel)
    np.testing.assert_allclose(r.translation_errors, [0.0, 0.1, 0.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(r.rotation_errors_deg, [0.0, 0.0, 2.0, 1.0], atol=1e-12)
    # e = δ⁻¹ ⊕ δ̂ = (R(θ)ᵀ (t̂ − t), θ̂ − θ): the second relation's (0, −0.1) rotated by −90°.
    np.testing.assert_allclose(r.errors[1], [-0.1, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(r.errors[2], [0.0, 0.0, -D(2.0)], atol=1e-12)
    assert r.count == r.total == 4 and r.covered_fraction == 1.0
    assert r.translation_mean == pytest.approx(0.15, abs=1e-12)
    assert r.translation_std == pytest.approx(math.sqrt(0.17 / 3), abs=1e-12)  # n − 1
    assert r.translation_sq_mean == pytest.approx(0.26 / 4, abs=1e-12)
    assert r.rotation_mean_deg == pytest.approx(0.75, abs=1e-12)
    assert r.rotation_std_deg == pytest.approx(math.sqrt(2.75 / 3), abs=1e-12)
    assert r.rotation_sq_mean_deg == pytest.approx(5.0 / 4, abs=1e-12)
    assert r.translation_max == pytest.approx(0.5) and r.rotation_max_deg == pytest.approx(2.0)
    assert r.summary() == "0.150 ± 0.238 m, 0.8 ± 1.0°, 100 % covered"
    d = r.as_dict()
    assert d["count"] == 4 and d["covered_fraction"] == 1.0 and d["max_duration"] is None
    assert d["translation_std"] == pytest.approx(0.238048, abs=1e-6)
    json.dumps(d, allow_nan=False)  # plain values


def test_one_relation_has_zero_std():
    times, poses, rel = hand_case()
    one = Relations(rel.t1[1:2], rel.t2[1:2], rel.deltas[1:2])
    r = relation_errors(times, poses, one)
    assert r.translation_mean == pytest.approx(0.1) and r.translation_std == 0.0


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_a_rigid_transform_of_the_whole_trajectory_leaves_the_errors_unchanged(seed):
    rng = np.random.default_rng(seed)
    n = 60
    times = np.cumsum(rng.uniform(0.1, 0.5, n))
    steps = np.column_stack([rng.uniform(0, 0.5, n), rng.normal(0, 0.05, n), rng.normal(0, 0.3, n)])
    poses = np.empty((n, 3))
    poses[0] = [0.0, 0.0, 0.0]
    for k in range(1, n):
        poses[k] = compose(poses[k - 1], steps[k])
    i = rng.integers(0, n, 40)
    j = rng.integers(0, n, 40)
    noisy = between(poses[i], poses[j]) + rng.normal(0, [0.05, 0.05, 0.02], (40, 3))
    # Stamps between samples too, so interpolation is part of the invariance.
    t1 = times[i] - 0.03
    t1[0] = times[i[0]]
    rel = Relations(t1, times[j], noisy)
    base = relation_errors(times, poses, rel)
    T = np.array([rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(-np.pi, np.pi)])
    moved = relation_errors(times, compose(T, poses), rel)
    np.testing.assert_array_equal(moved.covered, base.covered)
    np.testing.assert_allclose(moved.translation_errors, base.translation_errors, atol=1e-9)
    np.testing.assert_allclose(moved.rotation_errors_deg, base.rotation_errors_deg, atol=1e-9)
    assert base.translation_mean > 0.01  # the noise is scored


@pytest.mark.parametrize("heading", [0.0, 0.7, np.pi / 2, -2.5, np.pi])
def test_relations_are_in_the_robot_frame_a_rotated_start_changes_nothing(heading):
    # Driving 1 m forward and turning 0.3 rad each second, from any start heading, matches
    # the relation (1, 0, 0.3) in the robot frame exactly.
    poses = [np.array([3.0, -1.0, heading])]
    for _ in range(4):
        poses.append(compose(poses[-1], [1.0, 0.0, 0.3]))
    times = np.arange(5.0)
    rel = Relations(times[:-1], times[1:], np.tile([1.0, 0.0, 0.3], (4, 1)))
    r = relation_errors(times, np.stack(poses), rel)
    np.testing.assert_allclose(r.translation_errors, 0.0, atol=1e-12)
    np.testing.assert_allclose(r.rotation_errors_deg, 0.0, atol=1e-10)


def test_stamps_between_samples_are_interpolated_within_max_gap():
    times = np.array([0.0, 1.0, 2.0])
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.2], [2.0, 0.0, 0.4]])
    poses_at, ok = poses_at_stamps(times, poses, [0.5, 1.25, 1.0 + 4e-6, 2.5, -0.1])
    np.testing.assert_array_equal(ok, [True, True, True, False, False])
    np.testing.assert_allclose(poses_at[0], [0.5, 0.0, 0.1], atol=1e-12)
    np.testing.assert_allclose(poses_at[1], [1.25, 0.0, 0.25], atol=1e-12)
    np.testing.assert_array_equal(poses_at[2], poses[1])  # within the stamp tolerance: exact
    # From the pose at 0.5 to the one at 1.25: (0.75 along x, then in the frame at 0.5).
    expected = between([0.5, 0.0, 0.1], [1.25, 0.0, 0.25])
    rel = Relations([0.5], [1.25], [expected])
    r = relation_errors(times, poses, rel)
    assert r.translation_errors[0] == pytest.approx(0.0, abs=1e-12)
    # Neighbours 0.5 s and 0.25 s away: not covered with max_gap 0.4 s.
    with pytest.raises(InputError, match="covers no relation"):
        relation_errors(times, poses, rel, max_gap=0.4)


def test_a_gap_in_the_trajectory_is_not_bridged():
    times = np.array([0.0, 1.0, 5.0, 6.0])
    poses = np.column_stack([times, np.zeros(4), np.zeros(4)])
    _, ok = poses_at_stamps(times, poses, [0.5, 3.0, 4.5, 5.5])
    np.testing.assert_array_equal(ok, [True, False, False, True])
    _, ok = poses_at_stamps(times, poses, [3.0], max_gap=2.0)
    assert ok.tolist() == [True]


def test_coverage_fraction_when_the_trajectory_covers_half_the_relations():
    times = np.linspace(0.0, 10.0, 101)
    poses = np.column_stack([times, np.zeros_like(times), np.zeros_like(times)])
    t1 = np.array([0.0, 2.0, 9.0, 11.0, 13.0, 4.0])
    t2 = np.array([1.0, 3.0, 11.0, 12.0, 14.0, 6.0])
    deltas = np.column_stack([t2 - t1 + 0.1, np.zeros(6), np.zeros(6)])
    r = relation_errors(times, poses, Relations(t1, t2, deltas))
    assert r.covered.tolist() == [True, True, False, False, False, True]
    assert r.count == 3 and r.total == 6 and r.covered_fraction == 0.5
    np.testing.assert_array_equal(r.t1, [0.0, 2.0, 4.0])
    np.testing.assert_allclose(r.translation_errors, 0.1, atol=1e-9)
    assert r.summary().endswith("50 % covered")


def test_max_duration_scores_only_the_short_relations():
    times, poses, rel = hand_case()
    short = relation_errors(times, poses, rel, max_duration=1.5)  # the last one lasts 3 s
    assert short.total == 3 and short.count == 3 and short.max_duration == 1.5
    assert short.translation_mean == pytest.approx(0.1 / 3)
    assert short.as_dict()["max_duration"] == 1.5
    kept = select_relations(rel, min_duration=2.0)
    assert len(kept) == 1 and kept.t2[0] == 13.0
    # |t2 − t1|: a relation backwards in time counts by its length.
    back = Relations([5.0, 1.0], [4.0, 4.0], np.zeros((2, 3)))
    assert len(select_relations(back, max_duration=1.0)) == 1
    with pytest.raises(InputError, match="none of the 4 relations"):
        select_relations(rel, max_duration=0.5)


def test_errors_name_the_problem():
    times, poses, rel = hand_case()
    with pytest.raises(InputError, match=r"covers no relation of 4"):
        relation_errors(times + 100.0, poses, rel)
    with pytest.raises(InputError, match="strictly increasing"):
        relation_errors(times[::-1], poses, rel)
    with pytest.raises(ShapeError):
        relation_errors(times, poses[:, :2], rel)
    with pytest.raises(ShapeError, match="max_gap"):
        relation_errors(times, poses, rel, max_gap=-1.0)


def test_evaluate_scores_the_relations_of_the_data_set():
    ds = load_dataset("five-features", seed=0)
    truth = ds.truth
    assert truth.times is not None and truth.poses is not None
    i = np.arange(0, truth.times.size - 20, 7)
    rel = Relations(
        truth.times[i], truth.times[i + 20], between(truth.poses[i], truth.poses[i + 20])
    )
    ds = replace(ds, truth=replace(truth, relations=rel))
    res = run("dead-reckoning", ds)
    ev = evaluate(res, ds)
    scores = ev.scores.relations
    assert isinstance(scores, RelationError)
    direct = relation_errors(res.times, res.poses, rel)
    assert scores.count == direct.count == len(rel)
    assert scores.translation_mean == pytest.approx(direct.translation_mean, rel=1e-12)
    assert scores.translation_mean > 0  # dead reckoning drifts
    assert ev.metrics["relations"] == direct.as_dict()
    # Relations after the run: skipped with the reason, and in metrics.json as such.
    late = Relations(rel.t1 + 1e4, rel.t2 + 1e4, rel.deltas)
    ds_late = replace(ds, truth=replace(truth, relations=late))
    skipped = evaluate(res, ds_late).scores.relations
    assert isinstance(skipped, Skipped) and "covers no relation" in skipped.reason
    assert evaluate(res, ds_late).metrics["relations"] == {"skipped": skipped.reason}
    # No relations in the data set: no field.
    assert "relations" not in evaluate(res, load_dataset("five-features", seed=0)).metrics


@pytest.mark.realdata
@pytest.mark.parametrize(
    "name,count,short,stamps",
    [("intel", 2984, 1683, 1791), ("aces", 1279, 1163, 1218), ("fr079", 1685, 966, 989)],
)
def test_the_benchmark_relation_files(data_root, name, count, short, stamps):
    rel = read_relations(data_root / "laser" / "relations" / f"{name}.relations")
    assert len(rel) == count and rel.stamps.size == stamps
    assert len(select_relations(rel, max_duration=3.0)) == short
    # A trajectory through the distinct stamps (placeholder poses) covers every relation
    # exactly: the stamps match to the microsecond even as Unix times.
    t = rel.stamps
    r = relation_errors(t, np.column_stack([t - t[0], np.zeros((t.size, 2))]), rel)
    assert r.count == count and r.covered_fraction == 1.0
