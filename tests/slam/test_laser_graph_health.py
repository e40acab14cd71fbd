"""Graph SLAM's warnings: each rule fires at its stated threshold and not below it."""

from __future__ import annotations

import math

import numpy as np

from slamkit.estimation.health import LOST_SHARE, UNMATCHED_TRAVEL, UnmatchedStretch
from slamkit.slam.laser_graph.health import (
    CONTRADICTING_AT_LEAST,
    CONTRADICTING_SHARE,
    REFUSED_AT_LEAST,
    STRAINED_AT_LEAST,
    STRAINED_CHI2,
    run_warnings,
)


def _kinds(diagnostics, overrides=(), stretch=None, chi2=None, revisits=(0, 0)):  # type: ignore[no-untyped-def]
    found = run_warnings(
        diagnostics,
        list(overrides),
        stretch or UnmatchedStretch(),
        np.zeros(0) if chi2 is None else np.asarray(chi2, dtype=float),
        revisits,
    )
    return [w.kind for w in found], found


def test_a_clean_run_has_no_warning() -> None:
    kinds, _ = _kinds({"scans": 1000, "lost": 5, "loops_kept": 300, "loops_refused": 9})
    assert kinds == []


def test_glitches_name_the_first_one() -> None:
    kinds, found = _kinds({"scans": 10}, [(12.5, np.array([0.1, 0.0, math.radians(-60.0)]))])
    assert kinds == ["odometry_glitches"]
    assert "t = 12.50 s, -60°" in found[0].message


def test_lost_scans_above_their_share() -> None:
    n = 1000
    at = int(LOST_SHARE * n)
    assert _kinds({"scans": n, "lost": at})[0] == []
    assert _kinds({"scans": n, "lost": at + 1})[0] == ["track_lost"]


def test_the_longest_unmatched_stretch_by_travel() -> None:
    stretch = UnmatchedStretch()
    for k in range(30):  # 0.1 m steps: 10 unmatched, 5 matched, 15 unmatched, 1 matched
        stretch.add(1.0 + 0.1 * k, matched=10 <= k < 15, moved=0.1)
    stretch.add(8.9, matched=True, moved=0.1)
    stretch.add(9.0, matched=False, moved=0.5)
    assert (stretch.scans, round(stretch.travel, 9)) == (15, 1.5)
    assert (stretch.start, round(stretch.end, 9)) == (2.5, 3.9)
    assert _kinds({"scans": 40}, stretch=stretch)[0] == []
    stretch.add(9.1, matched=False, moved=UNMATCHED_TRAVEL)
    assert _kinds({"scans": 40}, stretch=stretch)[0] == ["unmatched_stretch"]


def test_refused_closures_must_outnumber_the_kept() -> None:
    n = REFUSED_AT_LEAST
    assert _kinds({"loops_refused": n, "loops_kept": n})[0] == []
    assert _kinds({"loops_refused": n, "loops_kept": n - 1})[0] == ["closures_refused"]
    assert _kinds({"loops_refused": n - 1, "loops_kept": 0})[0] == []


def test_a_strained_graph_needs_more_than_one_odd_edge() -> None:
    one = np.r_[np.ones(1749), 2 * STRAINED_CHI2]  # Intel: one such edge of 1,750
    assert _kinds({}, chi2=one)[0] == []
    many = np.r_[np.ones(100), np.full(STRAINED_AT_LEAST, 2 * STRAINED_CHI2)]
    kinds, found = _kinds({}, chi2=many)
    assert kinds == ["strained_graph"] and "3 of 103 loop closures" in found[0].message


def test_a_map_contradicts_itself_above_its_share_of_the_revisits() -> None:
    n = 200
    at = int(CONTRADICTING_SHARE * n)
    assert _kinds({}, revisits=(n, at))[0] == []
    kinds, found = _kinds({}, revisits=(n, at + 1))
    assert kinds == ["map_contradicts_itself"] and f"{at + 1} of {n} places" in found[0].message
    few = CONTRADICTING_AT_LEAST - 1  # a short log: a share alone is not enough
    assert _kinds({}, revisits=(few, few))[0] == []
