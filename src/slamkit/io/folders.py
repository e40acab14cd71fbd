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

__all__ = ["atomic_folder", "write_json"]


def write_json(path: str | Path, data: Any) -> None:
    """Write ``data`` as indented JSON (NaN written as null is not allowed: values must be
    finite or already converted to strings)."""
    Path(path).write_text(json.dumps(data, indent=2, allow_nan=False) + "\n", encoding="utf-8")


@contextlib.contextmanager
def atomic_folder(target: str | Path, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary folder beside ``target``; on success it replaces ``target`` in one
    rename, on any error it is removed and ``target`` is left as it was.

    Refuses to replace an existing non-empty ``target`` unless ``overwrite`` is set.
    """
    dest = Path(target)
    if dest.exists() and not dest.is_dir():
        raise InputError(f"{dest}: exists and is not a folder")
    if dest.exists() and any(dest.iterdir()) and not overwrite:
        raise InputError(f"{dest}: folder exists and is not empty (use --overwrite)")
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".partial", dir=dest.parent))
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
