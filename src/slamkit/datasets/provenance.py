"""Where a data set came from: the typed record the app layer reads, instead of keys in
``Dataset.metadata``.

A run's ``config.json`` must re-run it: it writes the data set's ``[dataset]`` table from
:attr:`Dataset.provenance <slamkit.datasets.stream.Dataset.provenance>` — the path read and
the reader that read it (so that the file goes to the same reader again), and the options
the loader resolved. ``metadata`` stays what it was meant for: descriptive counts a person
reads, never a channel between layers.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from slamkit.errors import InputError

__all__ = ["Provenance"]


@dataclass(frozen=True)
class Provenance:
    """How a :class:`~slamkit.datasets.stream.Dataset` was made.

    ``options`` are the loader's (or scenario's) resolved options as plain values (the
    fields of its options dataclass through :func:`slamkit.config.config_to_dict`); None
    when the loader records none (a run's ``config.json`` then writes the options it was
    given). ``path`` is the absolute path of a file read by path and ``reader`` the file
    reader that read it (one of :data:`slamkit.datasets.files.READERS`); both None for a
    registered or simulated data set. ``registered_as`` names the registered data set a
    path is the file of (a registered bag read by its path)."""

    options: Mapping[str, Any] | None = None
    path: str | None = None
    reader: str | None = None
    registered_as: str | None = None

    def __post_init__(self) -> None:
        if (self.path is None) != (self.reader is None):
            raise InputError("provenance: a path and its reader go together")
        if self.options is not None:
            object.__setattr__(self, "options", dict(self.options))  # a copy of the caller's

    def read_from(self, path: str, reader: str, registered_as: str | None = None) -> Provenance:
        """This record with the file ``path`` and the ``reader`` that read it."""
        return replace(self, path=path, reader=reader, registered_as=registered_as)

    def with_options(self, options: Mapping[str, Any]) -> Provenance:
        """This record with ``options`` as the resolved options."""
        return replace(self, options=options)
