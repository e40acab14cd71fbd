"""Output folders that are written completely or not at all."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from slamkit.errors import InputError

__all__ = [
    "atomic_folder",
    "check_output_folder",
    "fresh_folder",
    "remove_stale_partials",
    "same_folder",
    "write_json",
]


def write_json(path: str | Path, data: Any) -> None:
    """Write ``data`` as indented JSON (NaN written as null is not allowed: values must be
    finite or already converted to strings)."""
    Path(path).write_text(json.dumps(data, indent=2, allow_nan=False) + "\n", encoding="utf-8")


def check_output_folder(target: str | Path, *, overwrite: bool = False) -> Path:
    """Check, before any work, that ``target`` can be written as an output folder: not a
    file, not a non-empty folder (unless ``overwrite``), its parent creatable and writable.
    Creates the parent; raises :class:`~slamkit.errors.InputError` saying what is wrong."""
    dest = Path(target)
    if dest.exists() and not dest.is_dir():
        raise InputError(f"{dest}: exists and is not a folder")
    if dest.exists() and any(dest.iterdir()) and not overwrite:
        raise InputError(f"{dest}: folder exists and is not empty (use --overwrite)")
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(
            f"{dest}: cannot create the folder it goes in ({exc.strerror or exc})"
        ) from exc
    if not dest.parent.is_dir():
        raise InputError(f"{dest}: {dest.parent} is not a folder")
    try:
        probe = tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".probe", dir=dest.parent)
    except OSError as exc:
        raise InputError(f"{dest}: cannot write in {dest.parent} ({exc.strerror or exc})") from exc
    os.rmdir(probe)
    return dest


def fresh_folder(base: str | Path, *, avoid: str | Path | None = None) -> Path:
    """A default output folder that collides with nothing: ``base`` when it does not exist
    or is empty, else the first free ``base-2``, ``base-3``, … — so that a command run twice
    with its defaults writes two folders instead of refusing the second time. ``avoid`` (a
    folder, e.g. the one a ``config.json`` was read from) is never returned."""
    first = Path(base)
    banned = None if avoid is None else _resolved(Path(avoid))
    candidate, n = first, 1
    while True:
        free = not candidate.exists() or (candidate.is_dir() and not any(candidate.iterdir()))
        if free and (banned is None or _resolved(candidate) != banned):
            return candidate
        n += 1
        candidate = first.with_name(f"{first.name}-{n}")


def _resolved(path: Path) -> Path:
    try:
        return path.resolve()
    except OSError:  # pragma: no cover - a path the system cannot resolve
        return path.absolute()


def same_folder(a: str | Path, b: str | Path) -> bool:
    """Whether ``a`` and ``b`` name the same folder (after resolving links and ``..``)."""
    return _resolved(Path(a)) == _resolved(Path(b))


def remove_stale_partials(target: Path) -> list[Path]:
    """Remove the partial folders ``.NAME.PID.*.partial`` beside ``target`` whose process has
    ended (a run killed before it could clean up); returns those removed."""
    removed = []
    for partial in target.parent.glob(f".{target.name}.*.partial"):
        pid_text = partial.name[len(target.name) + 2 :].split(".", 1)[0]
        if not pid_text.isdigit() or _alive(int(pid_text)):
            continue
        shutil.rmtree(partial, ignore_errors=True)
        removed.append(partial)
    return removed


def _umask() -> int:
    """The process's umask (read by setting it, then restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


@contextlib.contextmanager
def atomic_folder(target: str | Path, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary folder beside ``target``; on success it replaces ``target`` in one
    rename, on any error it is removed and ``target`` is left as it was.

    Refuses to replace an existing non-empty ``target`` unless ``overwrite`` is set, and a
    target that cannot be written (:func:`check_output_folder`).
    """
    dest = check_output_folder(target, overwrite=overwrite)
    remove_stale_partials(dest)
    tmp = Path(
        tempfile.mkdtemp(prefix=f".{dest.name}.{os.getpid()}.", suffix=".partial", dir=dest.parent)
    )
    # mkdtemp makes the folder private (0700); a result folder gets the permissions of any
    # folder the user creates (0777 less the umask: group-readable under the usual 022/002)
    os.chmod(tmp, 0o777 & ~_umask())
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if dest.exists():
        old = dest.with_name(f".{dest.name}.old-{os.getpid()}")
        os.replace(dest, old)
    os.replace(tmp, dest)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
