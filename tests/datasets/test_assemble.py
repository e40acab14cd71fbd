"""The loader kit's one merge of event streams (slamkit.datasets.assemble)."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets.assemble import (
    EVENT_RANK,
    assemble_events,
    control_events,
    odometry_events,
    reading_events,
    scan_events,
    time_groups,
)
from slamkit.datasets.stream import Control, KnownPose, LandmarkReadings, LaserScan, Odometry
from slamkit.errors import InputError, ShapeError


def _kinds(events: tuple[object, ...]) -> list[tuple[str, float]]:
    return [(type(e).__name__, e.t) for e in events]  # type: ignore[attr-defined]


def test_streams_merge_by_time() -> None:
    odo = odometry_events([0.0, 1.0, 2.0], np.zeros((3, 3)))
    scans = scan_events([0.5, 1.5], np.ones((2, 4)))
    out = assemble_events(scans, odo)
    assert [e.t for e in out] == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert _kinds(out)[1] == ("LaserScan", 0.5)


def test_at_one_stamp_the_known_pose_then_the_motion_then_the_readings() -> None:
    t = 3.0
    scan = LaserScan(t, np.ones(2))
    reading = LandmarkReadings(t, np.ones((1, 2)), np.array([7]))
    control = Control(t, np.array([1.0, 0.0]), 0.1)
    known = KnownPose(t, np.zeros(3))
    out = assemble_events([scan], [reading], [control], [known])
    assert _kinds(out) == [
        ("KnownPose", t),
        ("Control", t),
        ("LaserScan", t),  # rank 2, first stream given
        ("LandmarkReadings", t),  # rank 2, second stream given
    ]
    assert [EVENT_RANK[type(e)] for e in out] == [0, 1, 2, 2]


def test_ties_of_one_rank_keep_the_order_of_the_streams_then_within_a_stream() -> None:
    first = [LaserScan(1.0, np.full(2, 1.0)), LaserScan(1.0, np.full(2, 2.0))]
    second = [LaserScan(1.0, np.full(2, 3.0))]
    out = assemble_events(second, first)
    assert [float(e.ranges[0]) for e in out] == [3.0, 1.0, 2.0]  # type: ignore[union-attr]
    out = assemble_events(first, second)
    assert [float(e.ranges[0]) for e in out] == [1.0, 2.0, 3.0]  # type: ignore[union-attr]


def test_one_unsorted_stream_is_sorted_stably() -> None:
    events = [
        Odometry(2.0, np.full(3, 0.0)),
        Odometry(1.0, np.full(3, 1.0)),
        Odometry(2.0, np.full(3, 2.0)),
        Odometry(1.0, np.full(3, 3.0)),
    ]
    out = assemble_events(events)
    assert [float(e.pose[0]) for e in out] == [1.0, 3.0, 0.0, 2.0]  # type: ignore[union-attr]


def test_stamps_are_kept_as_given() -> None:
    stamps = np.array([1134860000.0, 1134860000.0 + 1e-6, 0.1 + 0.2])
    out = assemble_events(odometry_events(stamps, np.zeros((3, 3))))
    assert [e.t for e in out] == sorted(stamps.tolist())
    assert all(type(e.t) is float for e in out)


def test_a_stamp_that_is_not_a_number_is_named() -> None:
    good = scan_events([0.0], np.ones((1, 2)))
    bad = odometry_events([0.0, np.nan], np.zeros((2, 3)))
    with pytest.raises(InputError, match=r"stream 1, event 1 \(Odometry\).*nan"):
        assemble_events(good, bad)


def test_an_unknown_event_type_is_refused() -> None:
    with pytest.raises(InputError, match="unknown event type str"):
        assemble_events(["not an event"])  # type: ignore[list-item]


def test_no_streams_and_empty_streams() -> None:
    assert assemble_events() == ()
    assert assemble_events([], scan_events([], np.zeros((0, 3)))) == ()


def test_reading_events_group_one_stamp_into_one_event() -> None:
    z = np.arange(8.0).reshape(4, 2)
    out = reading_events([1.0, 1.0, 2.0, 3.0], z, [4, 5, 6, 7])
    assert [(e.t, e.ids.tolist()) for e in out] == [(1.0, [4, 5]), (2.0, [6]), (3.0, [7])]
    np.testing.assert_array_equal(out[0].z, z[:2])
    z[0, 0] = 99.0  # the events hold copies
    assert out[0].z[0, 0] == 0.0
    one = reading_events([0.5, 0.5], [2.0, 3.0], [1, 2])  # range-only: a column
    assert one[0].z.shape == (2, 1)
    with pytest.raises(InputError, match="non-decreasing"):
        reading_events([2.0, 1.0], np.ones((2, 2)), [0, 1])
    with pytest.raises(ShapeError, match="expected 2 ids"):
        reading_events([1.0, 2.0], np.ones((2, 2)), [0])


def test_control_events_and_time_groups() -> None:
    out = control_events([1.0, 2.0], [[1.0, 0.1], [2.0, 0.2]], [0.5, 1.0])
    assert [(e.t, e.u.tolist(), e.dt) for e in out] == [
        (1.0, [1.0, 0.1], 0.5),
        (2.0, [2.0, 0.2], 1.0),
    ]
    with pytest.raises(ShapeError, match="control dt"):
        control_events([1.0], [[1.0, 0.0]], [0.5, 0.5])
    assert time_groups([0.0, 0.0, 1.0, 2.0, 2.0]) == ([0, 2, 3], [2, 3, 5])
    assert time_groups([]) == ([], [])


def test_the_kit_gives_the_order_of_the_landmark_loaders() -> None:
    """Controls and readings at the same stamps: each control before the readings at its
    end stamp, as MRCLAM, Plaza and Victoria Park interleaved them by hand before."""
    controls = control_events([1.0, 2.0, 3.0], np.ones((3, 2)), np.ones(3))
    readings = reading_events([0.5, 2.0, 2.0, 3.5], np.ones((4, 2)), [1, 2, 3, 4])
    out = assemble_events(controls, readings)
    assert _kinds(out) == [
        ("LandmarkReadings", 0.5),
        ("Control", 1.0),
        ("Control", 2.0),
        ("LandmarkReadings", 2.0),
        ("Control", 3.0),
        ("LandmarkReadings", 3.5),
    ]
