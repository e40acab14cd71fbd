"""Progress without a terminal (CI, ``tee``, ``nohup``): a plain line every N seconds."""

from __future__ import annotations

import io

import pytest
from rich.console import Console

from slamkit.cli.progress import PlainProgress, progress_bar


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_line_every_interval_with_the_share_of_work_the_elapsed_and_the_time_left():
    clock = FakeClock()
    lines: list[str] = []
    plain = PlainProgress("graph-slam on x", "events", lines.append, clock, interval=10.0)
    plain.counting("scans")
    clock.now += 5.0  # loading the data: counts towards the elapsed, not the rate
    plain(100, 2000)  # the first count starts the rate's clock
    assert lines == []  # 5 s: no line yet
    clock.now += 9.0
    plain(1000, 2000)  # 14 s since the start: one line
    # 900 scans in 9 s: 100 scans/s, 1000 scans left: 10 s
    assert lines == [
        "graph-slam on x: 50 % of scans (1,000/2,000), 0:00:14 elapsed, ~0:00:10 left, "
        "from the last 30 s's pace"
    ]
    clock.now += 3.0
    plain(1300, 2000)
    plain.tick()
    assert len(lines) == 1  # 3 s since the last line
    clock.now += 7.0
    plain.tick()  # called by the ticking thread: the state of the last count
    # the rate up to now (a stall makes the time left grow): 1200 scans in 19 s, 700 left
    assert lines[-1] == (
        "graph-slam on x: 65 % of scans (1,300/2,000), 0:00:24 elapsed, ~0:00:11 left, "
        "from the last 30 s's pace"
    )


def test_the_time_left_follows_the_rate_of_the_last_30_seconds():
    # a laser SLAM slows as its graph grows: the rate since the start would promise too little
    clock = FakeClock()
    lines: list[str] = []
    plain = PlainProgress("slam", "scans", lines.append, clock, interval=10.0)
    plain(0, 1000)
    clock.now += 10.0
    plain(500, 1000)  # 50 scans/s at first
    clock.now += 30.0
    plain(600, 1000)  # then 100 scans in 30 s: 400 left take 120 s, not the 27 s of the mean
    assert lines[-1] == (
        "slam: 60 % of scans (600/1,000), 0:00:40 elapsed, ~0:02:00 left, from the last 30 s's pace"
    )


def test_the_steps_after_the_count_are_named_with_their_own_elapsed_time():
    clock = FakeClock()
    lines: list[str] = []
    plain = PlainProgress("run", "events", lines.append, clock, interval=10.0)
    clock.now += 11.0
    plain.tick()  # nothing counted yet: the elapsed time alone
    assert lines == ["run: 0:00:11 elapsed"]
    plain(50, 50)
    clock.now += 1.0
    plain.stage("drawing the plots")
    clock.now += 32.0
    plain.tick()
    assert lines[-1] == "run: drawing the plots (0:00:32), 0:00:44 elapsed"
    assert len(lines) == 2


def test_progress_bar_without_a_terminal_prints_plain_lines_and_no_bar():
    out = io.StringIO()
    console = Console(file=out, force_terminal=False, width=200)
    with progress_bar("job", "events", console, interval=0.0) as progress:
        progress.counting("scans")
        progress(3, 4)
        progress.stage("writing the report page")
    text = out.getvalue()
    assert "job: 75 % of scans (3/4)" in text
    assert "job: writing the report page" in text
    assert "\x1b" not in text and "━" not in text  # no escape codes, no bar


def test_a_growing_pace_gives_the_range_from_the_pace_now_to_the_pace_rising():
    """Time per scan rising linearly, 10 ms + 20 µs × scans done (``T(x) = 0.01 x +
    1e-5 x²``): at 2000 of 4000 scans (60 s) the last 30 s's pace (from 1300 scans at
    29.9 s: 43 ms a scan) promises 86 s; rising as it has, the 140 s that are left."""
    from slamkit.pipeline.eta import TimeLeft

    clock = FakeClock()
    lines: list[str] = []
    plain = PlainProgress("graph-slam on x", "events", lines.append, clock, interval=1e9)
    plain.counting("scans", "growing")
    left = TimeLeft("growing")
    start = clock.now
    for done in range(0, 2001, 50):
        clock.now = start + 0.01 * done + 1e-5 * done**2
        plain(done, 4000)
        left.add(clock.now, done)
    low, high = left.estimate(4000) or (0.0, 0.0)
    assert low == pytest.approx(2000 * (60.0 - 29.9) / 700)  # 86.0 s
    assert high == pytest.approx(0.01 * 2000 + 1e-5 * (4000**2 - 2000**2))  # 140 s
    clock_text = [f"0:{int(v) // 60:02d}:{int(v) % 60:02d}" for v in (low, high)]
    assert plain.line() == (
        f"graph-slam on x: 50 % of scans (2,000/4,000), 0:01:00 elapsed, ~{clock_text[0]} to "
        f"{clock_text[1]} left, from the last 30 s's pace holding, or rising as it has since "
        "the start"
    )
    # a steady pace: one figure, the last 30 s's pace
    steady = TimeLeft()
    for done in range(0, 2001, 50):
        steady.add(0.02 * done, done)
    assert steady.estimate(4000) == pytest.approx((40.0, 40.0))


def test_a_sweeps_plain_line_says_the_runs_running_and_failed():
    clock = FakeClock()
    lines: list[str] = []
    plain = PlainProgress("sweep mc", "runs", lines.append, clock, interval=10.0)
    plain.note("2 running, 1 failed")
    plain(0, 8)
    clock.now += 10.0
    plain(4, 8)
    assert lines == [
        "sweep mc: 50 % of runs (4/8), 0:00:10 elapsed, 2 running, 1 failed, ~0:00:10 left, "
        "from the last 30 s's pace"
    ]
