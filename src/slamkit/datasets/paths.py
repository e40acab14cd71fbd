"""Where the real data sets live: one setting, ``SLAMKIT_DATA``.

The public data sets are never part of the package. Code finds them through
:func:`data_root`: an explicit argument, else the ``SLAMKIT_DATA`` environment variable, else a
``shared/data`` folder beside the current directory or beside the source checkout.
"""

from __future__ import annotations

import os
from pathlib import Path

from slamkit.errors import DataNotFoundError

__all__ = ["ENV_VAR", "data_root", "find_data_file", "find_data_root", "require_file"]

ENV_VAR = "SLAMKIT_DATA"


def _candidates() -> list[Path]:
    here = Path(__file__).resolve()
    # src/slamkit/datasets/paths.py -> the checkout is three levels up from the package.
    checkout = here.parents[3]
    return [Path.cwd().parent / "shared" / "data", checkout.parent / "shared" / "data"]


def find_data_root(explicit: str | os.PathLike[str] | None = None) -> Path | None:
    """The data folder, or ``None`` when no setting points at an existing folder."""
    if explicit is not None:
        p = Path(explicit).expanduser()
        return p if p.is_dir() else None
    env = os.environ.get(ENV_VAR)
    if env:
        p = Path(env).expanduser()
        return p if p.is_dir() else None
    for p in _candidates():
        if p.is_dir():
            return p
    return None


def data_root(explicit: str | os.PathLike[str] | None = None) -> Path:
    """The data folder; raises :class:`DataNotFoundError` saying how to set it."""
    root = find_data_root(explicit)
    if root is None:
        where = explicit if explicit is not None else os.environ.get(ENV_VAR)
        hint = f" ({where} is not a folder)" if where else ""
        raise DataNotFoundError(
            f"no data folder found{hint}: set {ENV_VAR} to the folder holding the public "
            "data sets (see docs/data.md)"
        )
    return root


def find_data_file(
    path: str | os.PathLike[str], root: str | os.PathLike[str] | None = None
) -> Path | None:
    """``path`` if it exists, else the same relative path under the data folder
    (:func:`find_data_root`) if it exists there, else ``None``: so that
    ``laser/relations/aces.relations`` names the shared file from any folder, and a command
    line never needs ``"$SLAMKIT_DATA/…"`` (which is ``/…`` when the variable is unset)."""
    p = Path(path).expanduser()
    if p.exists():
        return p
    folder = find_data_root(root)
    if not p.is_absolute() and folder is not None and (folder / p).exists():
        return folder / p
    return None


def require_file(relative: str, root: str | os.PathLike[str] | None = None) -> Path:
    """The path of ``relative`` under the data root; raises if it is missing."""
    path = data_root(root) / relative
    if not path.exists():
        raise DataNotFoundError(f"{path}: not found (needed under {ENV_VAR})")
    return path
