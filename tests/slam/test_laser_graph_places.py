"""What a loop closure of graph SLAM stands on besides its scan match: place recognition
(:mod:`slamkit.slam.laser_graph.places`: candidates found whatever the estimate's drift) and
the free-space check (:mod:`slamkit.slam.laser_graph.freespace`: a closure that lays either
side's walls in the other's open space is a contradiction)."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.geometry.pose2 import between, transform_points
from slamkit.slam.laser_graph.freespace import (
    MAX_CONTRADICTION,
    RESOLUTION,
    TOLERANCE_CELLS,
    FreeSpace,
    contradiction,
)
from slamkit.slam.laser_graph.places import SECTORS, PlaceIndex, signature


def _scan(
    walls: list[tuple[tuple[float, float], tuple[float, float]]], pose: np.ndarray
) -> np.ndarray:
    """A 360-beam scan from ``pose`` of line segments ``walls`` (first hit, 30 m reach), in the
    scan's frame."""
    angles = pose[2] + np.radians(np.arange(0.0, 360.0, 1.0))
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    best = np.full(angles.size, np.inf)
    for (ax, ay), (bx, by) in walls:
        e = np.array([bx - ax, by - ay])
        w = np.array([ax, ay]) - pose[:2]
        den = d[:, 0] * e[1] - d[:, 1] * e[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[0] * e[1] - w[1] * e[0]) / den  # along the beam
            s = (w[0] * d[:, 1] - w[1] * d[:, 0]) / den  # along the wall
        hit = (np.abs(den) > 1e-12) & (t > 0) & (s >= 0) & (s <= 1)
        best = np.where(hit & (t < best), t, best)
    ok = best < 30.0
    world = pose[:2] + d[ok] * best[ok, None]
    return transform_points(between(pose, np.zeros(3)), world)


def _box(
    x0: float, y0: float, x1: float, y1: float
) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    return [((x0, y0), (x1, y0)), ((x1, y0), (x1, y1)), ((x1, y1), (x0, y1)), ((x0, y1), (x0, y0))]


def _side(walls, poses: list[np.ndarray], frame: np.ndarray) -> FreeSpace:
    """The free space of scans of ``walls`` from ``poses``, in the frame of ``frame``."""
    origins = np.array([between(frame, p) for p in poses])
    clouds = [transform_points(o, _scan(walls, p)) for o, p in zip(origins, poses, strict=True)]
    return FreeSpace.from_scans(origins, clouds)


def test_a_free_cell_is_one_a_ray_crossed_away_from_every_end_point() -> None:
    free = FreeSpace.from_scans(np.zeros((1, 3)), [np.array([[3.05, 0.05]])])
    assert free.share_inside(np.array([[1.05, 0.05]])) == 1.0  # on the ray
    assert free.share_inside(np.array([[1.05, 0.55]])) == 0.0  # beside it
    near = 3.05 - TOLERANCE_CELLS * RESOLUTION  # within the tolerance of the end point
    assert free.share_inside(np.array([[near, 0.05]])) == 0.0
    assert free.share_inside(np.array([[near - RESOLUTION, 0.05]])) == 1.0
    assert free.share_inside(np.zeros((0, 2))) == 0.0


def test_the_same_room_seen_twice_does_not_contradict_itself() -> None:
    room = [*_box(-3.0, -3.0, 3.0, 3.0), ((-1.0, 1.0), (0.0, 1.0))]  # a shelf in it
    j = np.array([0.5, -0.5, 0.3])
    k = np.array([-0.8, 0.4, 2.0])
    place = _side(room, [j, j + np.array([0.4, 0.0, 0.0])], j)
    recent = _side(room, [k, k + np.array([0.0, -0.4, 0.0])], k)
    assert contradiction(place, recent, between(j, k)) == pytest.approx(0.0, abs=0.01)


@pytest.mark.parametrize("shift", [(0.0, 0.0, 0.0), (0.5, -0.3, 0.0), (0.0, 0.0, 0.3)])
def test_a_hall_laid_onto_a_narrow_room_contradicts_it(shift) -> None:
    """A wide hall placed on a narrow room (as an alias lays one place on another): each
    side's walls stand in the other's open space."""
    hall = _box(-4.0, -2.0, 4.0, 2.0)
    room = _box(-2.0, -4.0, 2.0, 4.0)
    origin = np.zeros(3)
    place = _side(room, [origin], origin)
    recent = _side(hall, [origin], origin)
    assert contradiction(place, recent, np.asarray(shift)) > 2 * MAX_CONTRADICTION
    # the same hall seen from elsewhere, put where it belongs
    pose = np.array([1.0, 1.0, 0.5])
    again = _side(hall, [pose], pose)
    assert contradiction(recent, again, pose) < MAX_CONTRADICTION / 4


def test_a_wall_seen_only_from_one_side_is_not_a_contradiction() -> None:
    """A door that closed between two visits: the new side's door stands in the old side's
    open space, but the old side's walls are not in the new side's (its rays stop at the
    door), so the smaller share, the contradiction, stays small."""
    hall = _box(-5.0, -2.0, 5.0, 2.0)
    door = [((2.0, -2.0), (2.0, 2.0))]  # closed later: cuts the hall at x = 2
    pose = np.array([-1.0, 0.0, 0.0])
    before = _side(hall, [pose], pose)
    after = _side([*hall, *door], [pose], pose)
    assert before.share_inside(after.points) > 0.05  # the door stands in the old free space
    assert contradiction(before, after, np.zeros(3)) < 0.01


def test_a_signature_turns_with_the_robot_and_its_ring_key_does_not() -> None:
    room = [*_box(-3.0, -2.0, 5.0, 4.0), ((1.0, 1.0), (2.0, 1.0)), ((-2.0, -1.0), (-2.0, 0.5))]
    pose = np.array([0.3, 0.2, 0.0])
    turned = np.array([0.3, 0.2, 2 * np.pi * 20 / SECTORS])  # 20 sectors round
    a, b = signature(_scan(room, pose)), signature(_scan(room, turned))
    rolled = np.roll(b, 20, axis=1)
    assert (rolled & a).sum() >= 0.95 * a.sum()  # cells on a sector's edge may change sides
    assert np.abs(a.mean(axis=1) - b.mean(axis=1)).sum() <= 0.05 * a.mean(axis=1).sum()
    assert (b & a).sum() < 0.5 * a.sum()  # unrolled, the two differ


def test_the_place_index_finds_the_revisited_room_and_the_turn_whatever_the_estimate() -> None:
    """Three rooms of different shapes visited, then the second again, turned by 100°: the
    index offers that visit first and the turn to within a sector; the estimate plays no
    part (the signatures are in each keyframe's own frame)."""
    rooms = [
        _box(0.0, 0.0, 6.0, 4.0),
        [*_box(0.0, 0.0, 3.0, 8.0), ((1.0, 5.0), (2.0, 5.0))],
        [*_box(0.0, 0.0, 9.0, 3.0), ((4.0, 0.0), (4.0, 1.5))],
    ]
    index = PlaceIndex()
    for walls in rooms:
        index.add(signature(_scan(walls, np.array([1.5, 1.5, 0.0]))))
    turn = np.radians(100.0)
    index.add(signature(_scan(rooms[1], np.array([1.6, 1.4, turn]))))
    found = index.candidates(3, np.array([True, True, True, False]), 2)
    assert found and found[0][0] == 1
    assert abs(found[0][1] - turn) <= 2 * np.pi / SECTORS


def test_a_loop_beyond_the_local_search_window_is_closed_by_place_recognition(monkeypatch) -> None:
    """Generated building 12 with the corpus's odometry errors (seed 1) and the local search
    held to 0.1 m, below the front end's drift at its revisits: only place recognition can
    close its loops (without it 0.330 m ATE, with it 0.124 m when this test was written;
    with the third session's front end, which followed people and stalls, 0.84 m and 0.12 m
    at 0.3 m)."""
    from slamkit.pipeline import run
    from slamkit.pipeline.evaluate import evaluate
    from slamkit.sim.buildings import build_building_dataset
    from slamkit.sim.odometry_errors import OdometryErrorModel, corrupt_odometry
    from slamkit.slam.laser_graph import estimator

    data, _ = corrupt_odometry(
        build_building_dataset(12), OdometryErrorModel(), np.random.default_rng(1)
    )
    narrow = {"loops": {"max_radius": 0.1}}
    found = run("graph-slam", data, config=narrow)
    assert found.output.diagnostics["places_verified"] > 10
    with_places = evaluate(found, data).scores.ate.rmse
    monkeypatch.setattr(estimator, "GLOBAL_EVERY", 10**9)
    without = evaluate(run("graph-slam", data, config=narrow), data).scores.ate.rmse
    assert with_places < 0.2 < 0.25 < without and without > 2.0 * with_places


def test_the_final_map_audit_finds_a_place_mapped_twice() -> None:
    """Two visits of one hall: the audit checks the revisits and finds none contradicting.
    Then the second visit's scans are of a narrow, deep room mapped onto the hall (a place
    held twice): every revisit checked contradicts."""
    from slamkit.slam.laser_graph.freespace import revisit_contradictions

    room = _box(-4.0, -2.0, 4.0, 2.0)
    away = _box(46.0, -2.0, 54.0, 2.0)  # the drive in between, far from the hall
    truth = [np.array([-1.0 + 0.2 * i, 0.0, 0.0]) for i in range(11)]
    truth += [np.array([49.0 + 0.2 * i, 0.0, 0.0]) for i in range(11)]
    truth += [np.array([1.0 - 0.2 * i, 0.3, np.pi]) for i in range(11)]
    points = [_scan(away if 11 <= i < 22 else room, p) for i, p in enumerate(truth)]
    travelled = np.arange(33) * 0.2 + np.r_[np.zeros(11), np.full(11, 50.0), np.full(11, 100.0)]
    poses = np.array(truth)
    checked, bad = revisit_contradictions(poses, points, np.zeros(3), travelled, 3.0)
    assert checked >= 2 and bad == []
    narrow = _box(-2.0, -4.0, 2.0, 4.0)
    points[22:] = [_scan(narrow, p) for p in truth[22:]]
    checked, bad = revisit_contradictions(poses, points, np.zeros(3), travelled, 3.0)
    assert checked >= 2 and len(bad) == checked


def test_people_walking_are_left_out_of_the_local_map(monkeypatch) -> None:
    """Generated building 0 with the corpus's odometry errors (seed 0): people walk its
    corridors, and a scan matched against a map that keeps them at every place they stood
    is pulled along with them (along a corridor the walls fix nothing else). Their points,
    seen through by the neighbouring keyframes, are left out (0.038 m ATE when this test was
    last measured); kept (a keyframe may then lose none), they pull the front end 0.3 m a
    keyframe at a time (0.33 m ATE). Seed 1, used before the odometry errors' backward steps
    were mended, now stretches the long west corridor with the wheel-radius error (0.155 m
    with people left out): see docs/laser_corpus.md, "Seeds"."""
    from slamkit.pipeline import run
    from slamkit.pipeline.evaluate import evaluate
    from slamkit.sim.buildings import build_building_dataset
    from slamkit.sim.odometry_errors import OdometryErrorModel, corrupt_odometry
    from slamkit.slam.laser_graph import estimator

    data, _ = corrupt_odometry(
        build_building_dataset(0), OdometryErrorModel(), np.random.default_rng(0)
    )
    cleared = run("graph-slam", data)
    assert cleared.output.diagnostics["transient_points"] > 100
    monkeypatch.setattr(estimator, "MAX_TRANSIENT", 0.0)
    kept = run("graph-slam", data)
    assert kept.output.diagnostics["transient_points"] == 0
    with_people = evaluate(kept, data).scores.ate.rmse
    assert evaluate(cleared, data).scores.ate.rmse < 0.1 < 0.2 < with_people
