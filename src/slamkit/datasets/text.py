"""A reader for the numeric text tables that public data sets come as.

Every real-data loader reads its files through :func:`read_table`: plain or gzip-compressed
(``.gz``, detected by suffix) text with one record per line, numbers separated by white space
(or by commas, ``delimiter=","``), and ``#`` starting a comment that runs to the end of the
line. Blank and comment-only lines are skipped.

Strict by default: the first line that has the wrong number of columns, a field that is not a
number, or a NaN/infinite value raises :class:`~slamkit.errors.DatasetFormatError` naming the
file and the line (1-based, counting every physical line). With ``lenient=True`` such lines
are skipped instead and reported in the returned :class:`NumericTable`.

Speed: lines are split in Python and all fields converted by NumPy in one call; only when that
bulk conversion fails is the offending line looked for field by field. A 100,000-line file
reads in about a tenth of a second.
"""

from __future__ import annotations

import gzip
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray
from slamkit.errors import DataNotFoundError, DatasetFormatError

__all__ = [
    "MAX_EXACT_INTEGER",
    "NumericTable",
    "ascii_fields",
    "check_times",
    "integer_column",
    "integer_values",
    "raise_at_first",
    "read_table",
    "read_text",
    "text_lines",
]

#: How many skipped line numbers a lenient read keeps (the count is always exact).
MAX_REPORTED_LINES = 20


@dataclass(frozen=True, eq=False)
class NumericTable:
    """The rows of a table, and what a lenient read left out."""

    values: FloatArray
    """The data ``(n, k)``, float64, every entry finite, rows in file order."""
    line_numbers: np.ndarray
    """``(n,)`` 1-based line of the file each row came from (for messages about a row)."""
    skipped: int = 0
    """How many malformed lines were skipped (always 0 for a strict read)."""
    skipped_lines: tuple[int, ...] = ()
    """The first :data:`MAX_REPORTED_LINES` skipped line numbers."""

    def __len__(self) -> int:
        return int(self.values.shape[0])


GZIP_MAGIC = b"\x1f\x8b"


def read_text(path: Path) -> str:
    """The text of ``path``: gzip-compressed when it starts with gzip's magic bytes (or is
    named ``*.gz``), UTF-8. The one way every reader opens a file: a missing file is a
    :class:`~slamkit.errors.DataNotFoundError`; a corrupt gzip stream (``zlib.error``,
    ``EOFError``, a bad header) and bytes that are not UTF-8 are a
    :class:`~slamkit.errors.DatasetFormatError` (the latter naming the line)."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise DataNotFoundError(f"{path}: not found") from None
    except OSError as exc:
        raise DataNotFoundError(f"{path}: cannot be read ({exc.strerror or exc})") from exc
    if raw[:2] == GZIP_MAGIC or path.suffix == ".gz":
        try:
            raw = gzip.decompress(raw)
        except (gzip.BadGzipFile, EOFError, zlib.error, OSError) as exc:
            raise DatasetFormatError(f"not a valid gzip file ({exc})", path) from exc
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise DatasetFormatError(f"not UTF-8 text ({exc.reason})", path, line) from exc


def head_lines(path: Path, count: int) -> list[str]:
    """The first ``count`` lines of a (gzip or plain) text file, for telling formats apart
    by their content without reading a whole log; bytes that are not UTF-8 are replaced and
    a damaged gzip stream ends the lines early (the reader proper reports both)."""
    try:
        with path.open("rb") as f:
            magic = f.read(2)
    except OSError as exc:
        raise DataNotFoundError(f"{path}: cannot be read ({exc.strerror or exc})") from exc
    opener = gzip.open if magic == GZIP_MAGIC else open
    lines: list[str] = []
    try:
        with opener(path, "rt", encoding="utf-8", errors="replace") as f:
            for line in f:
                lines.append(line.rstrip("\r\n"))
                if len(lines) >= count:
                    break
    except (gzip.BadGzipFile, EOFError, zlib.error, OSError):
        pass
    return lines


def text_lines(text: str) -> list[str]:
    """The lines of ``text``, split at ``\n`` only (a trailing ``\r`` removed), so that line
    numbers are those of an editor: ``str.splitlines`` also breaks at ``\x0b``, ``\x0c``,
    ``\x1c``-``\x1e``, ``\x85``, ``\u2028`` and ``\u2029``, which a corrupt file may hold."""
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return [ln[:-1] if ln.endswith("\r") else ln for ln in lines]


def ascii_fields(fields: list[str]) -> bool:
    """Whether every field is ASCII: numbers are read in ASCII only (Python's ``float`` and
    NumPy also take other scripts' digits, ``'١٢'`` as 12)."""
    return all(f.isascii() for f in fields)


def _split(line: str, delimiter: str | None) -> list[str]:
    """The fields of one line, comment removed; ``[]`` for a blank or comment-only line."""
    hash_at = line.find("#")
    if hash_at >= 0:
        line = line[:hash_at]
    if delimiter is None:
        return line.split()
    if not line.strip():
        return []
    return [field.strip() for field in line.split(delimiter)]


def _line_problem(fields: list[str], k: int) -> str | None:
    """Why one line is not a row of ``k`` finite numbers (``None`` if it is)."""
    if len(fields) != k:
        return f"expected {k} columns, got {len(fields)}"
    for j, field in enumerate(fields, start=1):
        try:
            value = float(field)
        except ValueError:
            return f"column {j}: expected a number, got {field!r}"
        if not np.isfinite(value):
            return f"column {j}: expected a finite number, got {field!r}"
    return None


def _split_lines(
    text: str, columns: int, delimiter: str | None, lenient: bool, p: Path
) -> tuple[list[str], list[int], list[int], DatasetFormatError | None]:
    """The fields of the lines that hold ``columns`` ASCII fields, their line numbers, the
    lines skipped (lenient), and the error of the first line that does not (strict: the
    lines after it are not read; it is raised after the values before it are checked)."""
    fields: list[str] = []
    numbers: list[int] = []
    bad: list[int] = []
    for i, line in enumerate(text_lines(text), start=1):
        parts = _split(line, delimiter)
        if not parts:
            continue
        if not ascii_fields(parts):
            if not lenient:
                why = "a field holds non-ASCII characters; expected ASCII numbers"
                return fields, numbers, bad, DatasetFormatError(why, p, i)
            bad.append(i)
            continue
        if len(parts) != columns:
            if not lenient:
                # Raised by the caller unless an earlier line holds a bad value: the first wins.
                why = f"expected {columns} columns, got {len(parts)}"
                return fields, numbers, bad, DatasetFormatError(why, p, i)
            bad.append(i)
            continue
        fields.extend(parts)
        numbers.append(i)
    return fields, numbers, bad, None


def read_table(
    path: str | Path,
    columns: int,
    *,
    lenient: bool = False,
    delimiter: str | None = None,
    min_rows: int = 1,
) -> NumericTable:
    """Read a numeric table of ``columns`` columns from ``path`` (``.gz``: gzip).

    ``delimiter=None`` splits on runs of white space (tabs, trailing blanks allowed); ``","``
    splits on commas (an empty field is an error). Raises :class:`DatasetFormatError` with the
    file and 1-based line of the first malformed line, unless ``lenient`` is true: then such
    lines are skipped and counted. A file with fewer than ``min_rows`` data rows (default
    1: an empty reading, GPS or landmark file is refused, never loaded as a data set with
    nothing in it) raises :class:`DatasetFormatError` too. A missing file raises
    :class:`~slamkit.errors.DataNotFoundError`.
    """
    if columns < 1:
        raise ValueError(f"columns: expected a positive number, got {columns}")
    p = Path(path)
    fields, numbers, bad, count_error = _split_lines(read_text(p), columns, delimiter, lenient, p)
    try:
        # Python's float() syntax, applied by NumPy to every field at once.
        values = np.array(fields, dtype=np.float64).reshape(-1, columns)
        ok = np.isfinite(values).all(axis=1)
    except ValueError:
        values, ok = _convert_rowwise(fields, columns)

    if not ok.all():
        rows = np.flatnonzero(~ok)
        if not lenient:
            r = int(rows[0])
            line_fields = fields[r * columns : (r + 1) * columns]
            why = _line_problem(line_fields, columns) or "malformed line"
            raise DatasetFormatError(why, p, numbers[r])
        bad.extend(numbers[int(r)] for r in rows)
        values = values[ok]
        numbers = np.asarray(numbers, dtype=np.int64)[ok].tolist()
    if count_error is not None:
        raise count_error

    if len(numbers) < min_rows:
        found = "none" if not numbers else str(len(numbers))
        skipped = f" ({len(bad)} malformed line(s) skipped)" if bad else ""
        raise DatasetFormatError(
            f"expected at least {min_rows} data row(s) of {columns} numbers, found "
            f"{found}{skipped}",
            p,
        )
    bad.sort()
    return NumericTable(
        values=np.ascontiguousarray(values, dtype=np.float64),
        line_numbers=np.asarray(numbers, dtype=np.int64),
        skipped=len(bad),
        skipped_lines=tuple(bad[:MAX_REPORTED_LINES]),
    )


def raise_at_first(table: NumericTable, bad: NDArray[np.bool_], path: Path, message: str) -> None:
    """Raise :class:`DatasetFormatError` at the line of the first row of ``table`` flagged in
    ``bad (n,)``, if any; ``message`` is formatted with that row's values (``{0}`` the first
    column), so a vectorised check still names the value, the file and the line."""
    rows = np.flatnonzero(bad)
    if rows.size:
        r = int(rows[0])
        raise DatasetFormatError(message.format(*table.values[r]), path, int(table.line_numbers[r]))


def check_times(table: NumericTable, path: Path, *, strict: bool, unit: str = "s") -> None:
    """Check that the first column (a time in ``unit``) increases (``strict``) or never
    decreases down the rows; else :class:`DatasetFormatError` at the first line that breaks
    the order."""
    step = np.diff(table.values[:, 0])
    what = "increasing" if strict else "non-decreasing"
    bad = np.concatenate([[False], step <= 0 if strict else step < 0])
    raise_at_first(
        table, bad, path, f"expected {what} times, got {{0:g}} {unit} after the row above"
    )


MAX_EXACT_INTEGER = 2**53
"""The largest integer a table reads exactly: numbers are parsed as float64, whose integers
are exact up to 2⁵³; an id beyond it would be silently rounded (or, cast to int64 from 2⁶³
on, wrapped to a negative number)."""


def integer_values(
    values: FloatArray, line_numbers: ArrayLike, what: str, path: Path
) -> NDArray[np.int64]:
    """``values`` as int64 when every one is an integer within ``±MAX_EXACT_INTEGER``, else
    a :class:`DatasetFormatError` naming ``what``, the file and the line of the first one
    that is not."""
    v = np.asarray(values, dtype=np.float64)
    bad = np.flatnonzero((v != np.round(v)) | ~(np.abs(v) <= MAX_EXACT_INTEGER))
    if bad.size:
        lines = np.asarray(line_numbers, dtype=np.int64).reshape(-1)
        raise DatasetFormatError(
            f"expected an integer {what} (at most 2^53 in magnitude), got {v[bad[0]]!r}",
            path,
            int(lines[bad[0]]),
        )
    return v.astype(np.int64)


def integer_column(table: NumericTable, col: int, what: str, path: Path) -> NDArray[np.int64]:
    """Column ``col`` of ``table`` through :func:`integer_values`."""
    return integer_values(table.values[:, col], table.line_numbers, what, path)


def _convert_rowwise(fields: list[str], columns: int) -> tuple[FloatArray, np.ndarray]:
    """Slow path after a failed bulk conversion: rows that hold a non-number become NaN and
    are marked bad, the rest are converted."""
    n = len(fields) // columns
    values = np.full((n, columns), np.nan)
    ok = np.zeros(n, dtype=bool)
    for r in range(n):
        row = fields[r * columns : (r + 1) * columns]
        try:
            values[r] = np.array(row, dtype=np.float64)
        except ValueError:
            continue
        ok[r] = bool(np.isfinite(values[r]).all())
    return values, ok
