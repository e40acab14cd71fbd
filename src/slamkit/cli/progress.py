"""The progress bar of the ``slamkit`` commands: count, rate and time left on stderr, and
the steps without a count (writing plots) named while they run."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import ProgressColumn, Task
from rich.text import Text

__all__ = ["ERR_CONSOLE", "ProgressHandle", "RateColumn", "progress_bar"]

ERR_CONSOLE = Console(stderr=True)
"""The stderr console of every command: progress bars and error lines share it, so a line
printed while a bar runs appears above the bar."""


class RateColumn(ProgressColumn):
    """Items per second of a progress bar (blank until there is a rate)."""

    def __init__(self, unit: str) -> None:
        super().__init__()
        self.unit = unit

    def render(self, task: Task) -> Text:
        speed = task.finished_speed or task.speed
        text = "" if speed is None else f"{speed:,.0f} {self.unit}/s"
        return Text(text, style="progress.data.speed")


class ProgressHandle:
    """What :func:`progress_bar` yields: call it as ``progress(done, total)``; ``stage(text)``
    names a step without a count (writing plots), shown with the spinner and elapsed time."""

    def __init__(self, update: Callable[..., None]) -> None:
        self.update = update

    def __call__(self, done: int, total: int) -> None:
        self.update(completed=done, total=total if total and total > 0 else None)

    def stage(self, text: str) -> None:
        self.update(description=text, completed=0, total=None)


@contextmanager
def progress_bar(
    label: str, unit: str = "events", console: Console | None = None
) -> Iterator[ProgressHandle]:
    """A transient rich progress bar on stderr (silent when stderr is not a terminal) with
    the count, the rate and the time left; yields the ``progress(done, total)`` callback the
    library functions take. Until the first call (total unknown) it shows a spinner and the
    elapsed time, never "0/None"."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        SpinnerColumn,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    err_console = console if console is not None else ERR_CONSOLE
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TaskProgressColumn(),
        MofNCompleteColumn(),
        TextColumn(unit),
        RateColumn(unit),
        TextColumn("elapsed"),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
        console=err_console,
        transient=True,
        disable=not err_console.is_terminal,
    ) as bar:
        task = bar.add_task(label, total=None)
        yield ProgressHandle(lambda **kw: bar.update(task, **kw))
