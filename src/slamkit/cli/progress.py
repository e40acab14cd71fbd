"""The progress of the ``slamkit`` commands on stderr.

On a terminal: a bar with what it counts (``scans 1,234/13,630``), the rate and the time
left, and then each step without a count (drawing the plots, writing the report) with a
spinner of its own, its name and its elapsed time. Without a terminal (CI, ``tee``,
``nohup``): a plain line every :data:`PLAIN_INTERVAL` seconds
(``graph-slam on x: 45 % of scans (1,234/2,742), 0:00:31 elapsed, ~0:00:38 left, from the
last 30 s's pace, rising as measured since the start``). The time left is
:class:`slamkit.pipeline.eta.TimeLeft`'s, in both."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from rich.console import Console
from rich.progress import ProgressColumn, Task
from rich.text import Text

if TYPE_CHECKING:  # the library is imported by the commands, not by `slamkit --help`
    from slamkit.pipeline.eta import Pace, TimeLeft

__all__ = [
    "ERR_CONSOLE",
    "PLAIN_INTERVAL",
    "PlainProgress",
    "ProgressHandle",
    "RateColumn",
    "progress_bar",
]

ERR_CONSOLE = Console(stderr=True)
"""The stderr console of every command: progress bars and error lines share it, so a line
printed while a bar runs appears above the bar."""

PLAIN_INTERVAL = 10.0
"""Seconds between two lines of progress without a terminal."""


def _clock_text(seconds: float) -> str:
    minutes, secs = divmod(int(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours:d}:{minutes:02d}:{secs:02d}"


def _left_text(low: float, high: float, between: str) -> str:
    """``0:00:38``, or ``0:00:38 to 0:01:20`` when the two differ by more than a tenth."""
    if high <= 1.1 * low + 1.0:
        return _clock_text(low)
    return f"{_clock_text(low)}{between}{_clock_text(high)}"


def _time_left(pace: Pace) -> TimeLeft:
    from slamkit.pipeline.eta import TimeLeft

    return TimeLeft(pace)


class RateColumn(ProgressColumn):
    """Items per second of a progress bar (blank until there is a rate)."""

    def __init__(self, unit: str) -> None:
        super().__init__()
        self.unit = unit

    def render(self, task: Task) -> Text:
        speed = task.finished_speed or task.speed
        unit = task.fields.get("unit", self.unit)
        text = "" if speed is None or task.total is None else f"{speed:,.0f} {unit}/s"
        return Text(text, style="progress.data.speed")


class _CountColumn(ProgressColumn):
    """``scans 1,234/13,630``: the unit and the count (blank without a total)."""

    def render(self, task: Task) -> Text:
        if task.total is None:
            return Text("")
        unit = task.fields.get("unit", "")
        text = f"{unit} {int(task.completed):,}/{int(task.total):,}"
        return Text(text, style="progress.download")


class _PercentColumn(ProgressColumn):
    def render(self, task: Task) -> Text:
        text = "" if task.total is None else f"{task.percentage:>3.0f}%"
        return Text(text, style="progress.percentage")


class _ElapsedColumn(ProgressColumn):
    def render(self, task: Task) -> Text:
        elapsed = task.finished_time if task.finished else task.elapsed
        return Text(f"elapsed {_clock_text(elapsed or 0.0)}", style="progress.elapsed")


class _LeftColumn(ProgressColumn):
    """``left 0:00:38`` (``left 0:00:38–0:01:20`` for a growing pace) from the task's
    ``left`` field (:meth:`TimeLeft.estimate`; blank without a total)."""

    def render(self, task: Task) -> Text:
        if task.total is None or task.finished:
            return Text("")
        left = task.fields.get("left")
        if left is None:
            return Text("left -:--:--", style="progress.remaining")
        low, high = left
        return Text(f"left {_left_text(low, high, '–')}", style="progress.remaining")


class ProgressHandle:
    """What :func:`progress_bar` yields: call it as ``progress(done, total)``;
    ``counting(unit, pace)`` says what the count is of (``"scans"``) and how its time per
    unit behaves (:class:`TimeLeft`); ``stage(text)`` names a step without a count (writing
    plots), shown with a spinner and its own elapsed time."""

    def __init__(
        self,
        update: Callable[..., None],
        stage: Callable[[str], None],
        counting: Callable[[str, Pace], None],
        note: Callable[[str], None] = lambda text: None,
    ) -> None:
        self._update = update
        self.stage = stage
        self.counting = counting
        self.note = note
        """``note(text)``: words shown beside the count (a sweep's ``2 running, 0
        failed``)."""

    def __call__(self, done: int, total: int) -> None:
        self._update(done, total)


class PlainProgress:
    """Progress as plain lines for a log: :meth:`tick` writes the state when ``interval``
    seconds have passed since the last line (or the start). ``clock`` and ``write`` are
    injected (``time.monotonic`` and a console's print in use)."""

    def __init__(
        self,
        label: str,
        unit: str,
        write: Callable[[str], None],
        clock: Callable[[], float] = time.monotonic,
        interval: float = PLAIN_INTERVAL,
    ) -> None:
        self.label = label
        self.unit = unit
        self._write = write
        self._clock = clock
        self.interval = interval
        self._start = clock()
        self._last_line = self._start
        self._lock = threading.Lock()
        self._done = 0
        self._total: int | None = None
        self._left = _time_left("steady")
        self._stage: str | None = None
        self._stage_start = self._start
        self._note = ""

    def __call__(self, done: int, total: int) -> None:
        with self._lock:
            self._left.add(self._clock(), done)
            self._done, self._total = done, (total if total and total > 0 else None)
        self.tick()

    def note(self, text: str) -> None:
        """Words shown after the count (``2 running, 0 failed``)."""
        with self._lock:
            self._note = text

    def counting(self, unit: str, pace: Pace = "steady") -> None:
        self.unit = unit
        self._left = _time_left(pace)

    def stage(self, text: str) -> None:
        with self._lock:
            self._stage, self._stage_start = text, self._clock()
        self.tick()

    def line(self) -> str:
        """The state now, as one line."""
        now = self._clock()
        elapsed = _clock_text(now - self._start)
        if self._stage is not None:
            return (
                f"{self.label}: {self._stage} ({_clock_text(now - self._stage_start)}), "
                f"{elapsed} elapsed"
            )
        if self._total is None:
            return f"{self.label}: {elapsed} elapsed"
        done, total = self._done, self._total
        text = (
            f"{self.label}: {100 * done / total:.0f} % of {self.unit} "
            f"({done:,}/{total:,}), {elapsed} elapsed"
        )
        if self._note:
            text += f", {self._note}"
        left = self._left.estimate(total, now)  # up to now: a stall makes it grow
        if left is not None:
            text += f", ~{_left_text(*left, ' to ')} left, from {self._left.basis}"
        return text

    def tick(self) -> None:
        """Write :meth:`line` if ``interval`` seconds have passed since the last line."""
        with self._lock:
            now = self._clock()
            if now - self._last_line < self.interval:
                return
            self._last_line = now
            text = self.line()
        self._write(text)


@contextmanager
def _ticking(plain: PlainProgress) -> Iterator[None]:
    """Call ``plain.tick()`` from a thread, so the lines keep coming during long steps that
    report nothing."""
    stop = threading.Event()

    def loop() -> None:
        while not stop.wait(min(1.0, plain.interval)):
            plain.tick()

    thread = threading.Thread(target=loop, name="slamkit-progress", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


@contextmanager
def progress_bar(
    label: str,
    unit: str = "events",
    console: Console | None = None,
    interval: float = PLAIN_INTERVAL,
) -> Iterator[ProgressHandle]:
    """The progress of one command on stderr; yields the ``progress(done, total)``
    callback the library functions take (:class:`ProgressHandle`).

    On a terminal: a transient rich bar with the count in ``unit`` (or what ``counting``
    says), the rate and the time left; until the first call (total unknown) a spinner and
    the elapsed time, never "0/None"; each ``stage(text)`` then replaces the bar with a
    spinner, the stage's name and its elapsed time. Without a terminal: a
    :class:`PlainProgress` line every ``interval`` seconds."""
    err_console = console if console is not None else ERR_CONSOLE
    if not err_console.is_terminal:
        plain = PlainProgress(
            label,
            unit,
            lambda text: err_console.print(text, markup=False, highlight=False, soft_wrap=True),
            interval=interval,
        )
        with _ticking(plain):
            yield ProgressHandle(plain, plain.stage, plain.counting, plain.note)
        return

    from rich.progress import BarColumn, Progress, SpinnerColumn, TaskID, TextColumn

    from slamkit.pipeline.eta import RATE_WINDOW

    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        _PercentColumn(),
        _CountColumn(),
        RateColumn(unit),
        _ElapsedColumn(),
        _LeftColumn(),
        console=err_console,
        transient=True,
        speed_estimate_period=RATE_WINDOW,  # the plain line's window too
    ) as bar:
        current: list[TaskID] = [bar.add_task(label, total=None, unit=unit)]
        pace: list[TimeLeft] = [_time_left("steady")]

        def update(done: int, total: int) -> None:
            pace[0].add(time.monotonic(), done)
            left = pace[0].estimate(total, time.monotonic()) if total and total > 0 else None
            bar.update(
                current[0],
                completed=done,
                total=total if total and total > 0 else None,
                left=left,
                pace=pace[0].pace,
            )

        def stage(text: str) -> None:
            bar.update(current[0], visible=False)
            bar.stop_task(current[0])
            current[0] = bar.add_task(f"{label}: {text}", total=None)
            bar.refresh()  # the step's name at once, not at the next tick

        def counting(new_unit: str, new_pace: Pace = "steady") -> None:
            pace[0] = _time_left(new_pace)
            bar.update(current[0], unit=new_unit)

        def note(text: str) -> None:
            bar.update(current[0], description=f"{label} ({text})")

        yield ProgressHandle(update, stage, counting, note)
