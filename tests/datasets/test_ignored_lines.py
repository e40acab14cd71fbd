"""A CARMEN log's SYNC and TRUEPOS lines are read past on purpose and counted, with the
reason, in the reading summary of both CARMEN readers (and of a run's metrics.json)."""

from __future__ import annotations

from pathlib import Path

import pytest

from slamkit.datasets.carmen_parse import IGNORED_MESSAGES, ignored_lines
from slamkit.datasets.files import load_file
from slamkit.datasets.reading import ReadingSummary
from slamkit.datasets.stream import LaserScan

SYNC = f"SYNC lines ({IGNORED_MESSAGES['SYNC']})"
TRUEPOS = f"TRUEPOS lines ({IGNORED_MESSAGES['TRUEPOS']})"


def _flaser(k: int) -> str:
    t = 10.0 + k
    ranges = " ".join(f"{1.0 + 0.01 * i:g}" for i in range(181))
    x = 0.1 * k
    return f"FLASER 181 {ranges} {x} 0 0 {x} 0 0 {t} host {t}"


def _log(tmp_path: Path, corrected: bool) -> Path:
    """Four scans; two SYNC lines and three TRUEPOS lines between them (the corrected log
    with a NEFF line after each scan)."""
    lines = ["PARAM laser_front_laser_fov 180 host 0"]
    for k in range(4):
        lines.append(_flaser(k))
        if corrected:
            lines.append("NEFF 30")
        if k < 3:
            lines.append(f"TRUEPOS {0.1 * k} 0 0 {0.1 * k} 0 0 {10.0 + k} host {10.0 + k}")
        if k % 2 == 0:
            lines.append(f"SYNC 1 {10.0 + k} host {10.0 + k}")
    path = tmp_path / ("run-corrected.log" if corrected else "run.log")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize(
    ("corrected", "reader"), [(True, "carmen-corrected"), (False, "carmen-raw")]
)
def test_sync_and_truepos_lines_are_counted_as_ignored(
    tmp_path: Path, corrected: bool, reader: str
) -> None:
    ds = load_file(_log(tmp_path, corrected))
    assert ds.provenance.reader == reader
    assert sum(isinstance(e, LaserScan) for e in ds.events) == 4
    summary = ds.reading
    assert summary is not None
    assert (summary.records, summary.used, dict(summary.dropped)) == (4, 4, {})
    assert dict(summary.ignored) == {SYNC: 2, TRUEPOS: 3}
    assert not summary.clean
    assert summary.lines()[1] == f"  ignored 2 {SYNC}, 3 {TRUEPOS}"
    assert ReadingSummary.from_dict(summary.to_dict()) == summary


def test_a_log_without_them_ignores_nothing(tmp_path: Path) -> None:
    path = tmp_path / "plain.log"
    path.write_text("\n".join(_flaser(k) for k in range(3)) + "\n", encoding="utf-8")
    summary = load_file(path).reading
    assert summary is not None and dict(summary.ignored) == {} and summary.clean
    assert ignored_lines({"FLASER": 3, "ODOM": 7}) == {}


def test_a_summary_written_before_the_ignored_counts_still_reads() -> None:
    old = {"file": "a.log", "records": 3, "used": 3, "dropped": {}, "repaired": {}, "notes": []}
    assert ReadingSummary.from_dict(old).ignored == {}
