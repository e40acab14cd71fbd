"""What every ``slamkit`` command shares: consoles, the known-error decorator, the progress
bar and the splitting of a configuration file into its tables."""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, ParamSpec, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import ProgressColumn, Task
from rich.text import Text

from slamkit.errors import SlamkitError

P = ParamSpec("P")
R = TypeVar("R")

console = Console()
err_console = Console(stderr=True)


def _quiet_types() -> None:
    """Help screens without type noise: typer (0.2x) prints a type after every option —
    ``<bool>`` after each flag and ``--help``, ``<str>`` after every free-text option — which
    says nothing the option's name and help do not. Flags and plain strings are shown
    without one; choices (``<lm|gn|dogleg>``), numbers and paths keep theirs. Applied once,
    to typer's option class (a no-op on versions without ``display_type_rich``)."""
    from typer.core import TyperArgument, TyperOption

    for cls in (TyperOption, TyperArgument):
        original = getattr(cls, "display_type_rich", None)
        if original is None or getattr(original, "slamkit_quiet", False):
            continue
        cls.display_type_rich = _quiet(original)  # type: ignore[method-assign, assignment]


def _quiet(original: Callable[[Any, Any], str | None]) -> Callable[[Any, Any], str | None]:
    def display_type_rich(self: Any, ctx: Any) -> str | None:
        if self.metavar is None and getattr(self, "is_flag", False):
            return None
        shown = original(self, ctx)
        return None if shown == "<str>" else shown

    display_type_rich.slamkit_quiet = True  # type: ignore[attr-defined]
    return display_type_rich


_quiet_types()


class Terminated(KeyboardInterrupt):
    """Raised by the SIGTERM handler the ``slamkit`` command installs, so that a terminated
    run unwinds (and removes its partial output) as an interrupted one does."""


def terminate(signum: int, frame: object) -> None:
    """The SIGTERM handler: unwind like Ctrl-C."""
    raise Terminated


def known_errors(fn: Callable[P, R]) -> Callable[P, R]:
    """Turn slamkit's own errors into one red line on stderr and exit code 1; an interrupt
    (Ctrl-C, or SIGTERM) into one line and exit code 130 (143 for SIGTERM). Output folders
    are written atomically, so an interrupted run leaves nothing behind."""

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            return fn(*args, **kwargs)
        except KeyboardInterrupt as exc:
            what = "terminated" if isinstance(exc, Terminated) else "interrupted"
            err_console.print(f"{what}; nothing was written", highlight=False)
            raise typer.Exit(143 if isinstance(exc, Terminated) else 130) from None
        except SlamkitError as exc:
            # escaped: a message naming a "[mapping]" table is not rich markup
            err_console.print(
                f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True
            )
            raise typer.Exit(1) from None

    return wrapper


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
def progress_bar(label: str, unit: str = "events") -> Iterator[ProgressHandle]:
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


def split_config(
    path: Path | None, main_table: str
) -> tuple[dict[str, Any], dict[str, Any], int | None]:
    """A TOML/JSON configuration file's ``[main_table]`` and ``[dataset]`` options and its
    ``seed`` (:func:`slamkit.app.runconfig.read_run_config`, which also gives the data set the
    file names and its preset)."""
    from slamkit.app.runconfig import read_run_config

    cfg = read_run_config(path, main_table)
    return dict(cfg.settings), dict(cfg.dataset_options), cfg.seed
