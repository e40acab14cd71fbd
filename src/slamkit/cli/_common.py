"""What every ``slamkit`` command shares: consoles, the command groups, the options several
commands take, the known-error decorator, the progress bar, the default output folder and the
splitting of a configuration file into its tables."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, ParamSpec, TypeVar

import typer
from rich.console import Console
from rich.markup import escape

from slamkit.cli.progress import ERR_CONSOLE, ProgressHandle, progress_bar
from slamkit.errors import SlamkitError

__all__ = [
    "DataRootOption",
    "ProgressHandle",
    "command_group",
    "console",
    "err_console",
    "known_errors",
    "output_folder",
    "progress_bar",
    "split_config",
    "terminate",
]

P = ParamSpec("P")
R = TypeVar("R")

console = Console()
err_console = ERR_CONSOLE

DataRootOption = Annotated[
    Path | None,
    typer.Option(help="Folder of the real data sets (else $SLAMKIT_DATA).", show_default=False),
]
"""The ``--data-root`` option of every command that loads a data set by name."""


def command_group(help: str, **kwargs: Any) -> typer.Typer:
    """A ``slamkit`` command group (``slamkit eval``, ``slamkit sweep``, ...): its help
    when called without a command, no shell-completion options, slamkit's own error
    lines instead of typer's tracebacks. ``kwargs`` go to :class:`typer.Typer`."""
    return typer.Typer(
        help=help,
        no_args_is_help=True,
        add_completion=False,
        pretty_exceptions_enable=False,
        **kwargs,
    )


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


def output_folder(out: Path | None, name: str, *, config: Path | None = None) -> Path:
    """Where a command writes: ``--out`` as given, else a fresh ``results/NAME`` (a numbered
    ``results/NAME-2``, … when that one is taken: :func:`slamkit.io.fresh_folder`), so a
    command run twice with its defaults never collides. Never the folder the configuration
    file ``config`` was read from (a re-run from a run's ``config.json`` would replace the
    files it re-runs): an ``--out`` naming it is a :class:`~slamkit.errors.ConfigError`."""
    from slamkit.errors import ConfigError
    from slamkit.io import fresh_folder, same_folder

    home = None if config is None else config.parent
    if out is None:
        return fresh_folder(Path("results") / name, avoid=home)
    if home is not None and same_folder(out, home):
        raise ConfigError(
            f"--out {out}: the folder {config} was read from; a re-run writes another folder "
            "(leave out --out for a fresh one)"
        )
    return out


def split_config(
    path: Path | None, main_table: str
) -> tuple[dict[str, Any], dict[str, Any], int | None]:
    """A TOML/JSON configuration file's ``[main_table]`` and ``[dataset]`` options and its
    ``seed`` (:func:`slamkit.app.runconfig.read_run_config`, which also gives the data set the
    file names and its preset)."""
    from slamkit.app.runconfig import read_run_config

    cfg = read_run_config(path, main_table)
    return dict(cfg.settings), dict(cfg.dataset_options), cfg.seed
