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

from slamkit.errors import SlamkitError

P = ParamSpec("P")
R = TypeVar("R")

console = Console()
err_console = Console(stderr=True)


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


@contextmanager
def progress_bar(label: str, unit: str = "events") -> Iterator[Callable[[int, int], None]]:
    """A transient rich progress bar on stderr (silent when stderr is not a terminal);
    yields the ``progress(done, total)`` callback the library functions take."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} " + unit),
        TimeElapsedColumn(),
        console=err_console,
        transient=True,
        disable=not err_console.is_terminal,
    ) as bar:
        task = bar.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


def split_config(
    path: Path | None, main_table: str
) -> tuple[dict[str, Any], dict[str, Any], int | None]:
    """Read a TOML/JSON configuration file into its ``[main_table]`` and ``[dataset]`` tables
    and an optional top-level integer ``seed``; any other top-level key is an error. A
    ``name`` key in either table, and a ``path`` key in ``[dataset]``, are informational (as
    written in ``config.json``) and dropped."""
    if path is None:
        return {}, {}, None
    from slamkit.config import load_config_file
    from slamkit.errors import ConfigError

    raw = load_config_file(path)
    unknown = sorted(set(raw) - {main_table, "dataset", "seed"})
    if unknown:
        raise ConfigError(
            f"{path}: unknown section(s) {', '.join(unknown)}; expected {main_table}, dataset, seed"
        )
    seed = raw.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
        raise ConfigError(f"{path}: seed must be an integer, got {seed!r}")
    tables = []
    for name in (main_table, "dataset"):
        table = raw.get(name, {})
        if not isinstance(table, dict):
            raise ConfigError(f"{path}: [{name}] must be a table of settings")
        dropped = {"name", "path"} if name == "dataset" else {"name"}
        tables.append({k: v for k, v in table.items() if k not in dropped})
    return tables[0], tables[1], seed
