"""What a reader did to a file: the reading summary every real-data reader returns.

Real logs are quirky rather than broken: stamps of zero, stamps that repeat or go back,
stamps with six significant digits, a ``LaserScan.angle_max`` half a beam off, a field of
view written in radians. A reader repairs what it can, drops what it cannot use, and says so
here, by reason, so that the user reads in one or two lines what happened to their file.

:class:`ReadingSummary` is a typed record (not keys in ``Dataset.metadata``); the run prints
:meth:`ReadingSummary.lines`, and writes :meth:`ReadingSummary.to_dict` into
``metrics.json`` under ``"reading"`` and onto the report page.

:func:`check_dropped_share` is the one rule that keeps a lenient read honest: a reader may
drop malformed lines, but never more than :data:`MAX_DROPPED_SHARE` of a file's records
(beyond :data:`FEW_DROPPED`) without an error. Two scans of 406 are a failure, not a result.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from slamkit.errors import DatasetFormatError, InputError

__all__ = ["FEW_DROPPED", "MAX_DROPPED_SHARE", "ReadingSummary", "check_dropped_share"]

MAX_DROPPED_SHARE = 0.1
"""The largest share of a file's records (scans, odometry lines) a reader may drop without
an error, lenient or not."""
FEW_DROPPED = 2
"""Dropping this many records is never an error, whatever the share: a bad line or two in
a short file is a quirk, not a file the reader cannot trust."""


@dataclass(frozen=True)
class ReadingSummary:
    """What reading one file did.

    ``records`` is what the file held of the kind that matters (scans for a laser log), and
    ``used`` how many of them the data set has. ``dropped`` and ``repaired`` count records by
    reason (a short phrase such as ``"stamp re-made from the line order"``); ``ignored``
    counts the lines of other kinds that were read and deliberately not used, by kind and
    reason (``"SYNC lines (clock sync between hosts; not needed)"``); ``notes`` are
    one-off remarks about the whole file (``"angle_max is one increment off; the increment
    wins"``).
    """

    file: str
    records: int
    used: int
    what: str = "scans"
    dropped: Mapping[str, int] = field(default_factory=dict)
    repaired: Mapping[str, int] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    ignored: Mapping[str, int] = field(default_factory=dict)

    @property
    def clean(self) -> bool:
        """True when nothing was dropped, repaired, ignored or noted."""
        return not (self.dropped or self.repaired or self.ignored or self.notes)

    def lines(self) -> list[str]:
        """One line (two when something was repaired, ignored or noted) for the console."""
        head = f"read {self.file}: {self.used} of {self.records} {self.what}"
        if self.dropped:
            head += "; dropped " + _counts(self.dropped)
        out = [head]
        tail = []
        if self.repaired:
            tail.append("repaired " + _counts(self.repaired))
        if self.ignored:
            tail.append("ignored " + _counts(self.ignored))
        tail.extend(self.notes)
        if tail:
            out.append("  " + "; ".join(tail))
        return out

    def to_dict(self) -> dict[str, Any]:
        """Plain values for ``metrics.json``."""
        return {
            "file": self.file,
            "what": self.what,
            "records": self.records,
            "used": self.used,
            "dropped": dict(self.dropped),
            "repaired": dict(self.repaired),
            "ignored": dict(self.ignored),
            "notes": list(self.notes),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ReadingSummary:
        """The summary :meth:`to_dict` wrote (``metrics.json``'s ``"reading"``, read back for
        the report page). A value of the wrong kind raises :class:`~slamkit.errors.InputError`
        naming the key; ``what``, ``dropped``, ``repaired``, ``ignored`` and ``notes`` may be
        missing (a ``metrics.json`` written before they were counted)."""

        def count(key: str) -> int:
            value = data.get(key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise InputError(f"reading.{key}: expected a count, got {value!r}")
            return value

        def by_reason(key: str) -> dict[str, int]:
            value = data.get(key, {})
            if not isinstance(value, Mapping) or not all(
                isinstance(n, int) and not isinstance(n, bool) for n in value.values()
            ):
                raise InputError(f"reading.{key}: expected counts by reason, got {value!r}")
            return {str(reason): n for reason, n in value.items()}

        notes = data.get("notes", [])
        if not isinstance(notes, list | tuple) or not all(isinstance(n, str) for n in notes):
            raise InputError(f"reading.notes: expected a list of remarks, got {notes!r}")
        return cls(
            file=str(data.get("file", "?")),
            records=count("records"),
            used=count("used"),
            what=str(data.get("what", "scans")),
            dropped=by_reason("dropped"),
            repaired=by_reason("repaired"),
            notes=tuple(notes),
            ignored=by_reason("ignored"),
        )


def _counts(counts: Mapping[str, int]) -> str:
    return ", ".join(f"{n} {reason}" for reason, n in counts.items())


def check_dropped_share(
    path: str | Path,
    records: int,
    dropped: int,
    what: str = "scans",
    reasons: Mapping[str, int] | None = None,
) -> None:
    """Raise :class:`DatasetFormatError` when more than :data:`MAX_DROPPED_SHARE` of the
    ``records`` (and more than :data:`FEW_DROPPED`) were ``dropped``: a read that keeps too
    little of a file is not a result. ``reasons`` (the drops by reason) are named in the
    message."""
    if dropped > FEW_DROPPED and dropped > MAX_DROPPED_SHARE * records:
        why = f" ({_counts(reasons)})" if reasons else ""
        raise DatasetFormatError(
            f"{dropped} of {records} {what} could not be used{why}, more than "
            f"{MAX_DROPPED_SHARE:.0%}; the file is not a log this reader can trust",
            path,
        )
