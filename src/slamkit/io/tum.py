"""TUM trajectory text files: ``timestamp tx ty tz qx qy qz qw`` per line.

SE(2) poses are written as planar SE(3) poses (z = 0, rotation about z), which is what the
TUM/evo tools read. Reading projects back onto the plane (the yaw of the quaternion).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.datasets.text import ascii_fields, read_text, text_lines
from slamkit.errors import DatasetFormatError
from slamkit.geometry import wrap_angle

__all__ = ["format_tum", "read_tum", "read_tum_matrices", "read_tum_rows", "write_tum"]


def format_tum(times: ArrayLike, poses: ArrayLike) -> str:
    """The text of a TUM file for ``times (N,)`` and SE(2) ``poses (N, 3)``."""
    t = as_array(times, "times", (None,))
    p = as_array(poses, "poses", (t.size, 3))
    half = 0.5 * p[:, 2]
    cols = np.column_stack(
        [t, p[:, 0], p[:, 1], np.zeros_like(t), np.zeros_like(t), np.zeros_like(t),
         np.sin(half), np.cos(half)]
    )  # fmt: skip
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    # Stamps keep 16 significant digits: a Unix time in seconds needs 10 before the point,
    # and the Freiburg relations name scan stamps to the microsecond.
    lines += [f"{row[0]:.16g} " + " ".join(f"{v:.9g}" for v in row[1:]) for row in cols]
    return "\n".join(lines) + "\n"


def write_tum(path: str | Path, times: ArrayLike, poses: ArrayLike) -> None:
    """Write a TUM trajectory file (see :func:`format_tum`)."""
    Path(path).write_text(format_tum(times, poses), encoding="utf-8")


def read_tum_rows(path: str | Path) -> tuple[FloatArray, list[int]]:
    """The rows ``(N, 8)`` of a TUM file and their 1-based line numbers, checked: eight
    ASCII numbers per line, finite, and stamps strictly increasing. Any fault is a
    :class:`DatasetFormatError` naming the file and the line.

    Stamps out of order are refused here rather than sorted: the TUM tools (and evo) keep
    the file's order too, and a trajectory whose stamps go back or repeat was written wrong
    (two writers interleaved, a clock reset) in a way no reader can undo; everything that
    pairs poses by stamp downstream needs them strictly increasing."""
    p = Path(path)
    rows: list[list[float]] = []
    lines: list[int] = []
    for lineno, line in enumerate(text_lines(read_text(p)), start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        parts = text.replace(",", " ").split()
        if len(parts) != 8:
            raise DatasetFormatError(f"expected 8 numbers, got {len(parts)}", p, lineno)
        if not ascii_fields(parts):
            raise DatasetFormatError("expected ASCII numbers, got other characters", p, lineno)
        try:
            row = [float(v) for v in parts]
        except ValueError as exc:
            raise DatasetFormatError(f"not a number: {exc}", p, lineno) from None
        if not all(math.isfinite(v) for v in row):
            raise DatasetFormatError("expected finite numbers, got NaN or infinity", p, lineno)
        if rows and not row[0] > rows[-1][0]:
            raise DatasetFormatError(
                f"expected strictly increasing stamps, got {parts[0]} after "
                f"{rows[-1][0]!r} (line {lines[-1]})",
                p,
                lineno,
            )
        rows.append(row)
        lines.append(lineno)
    if not rows:
        raise DatasetFormatError("no poses in the file", p)
    return np.asarray(rows), lines


def read_tum(path: str | Path) -> tuple[FloatArray, FloatArray]:
    """Read a TUM file into ``times (N,)`` and SE(2) poses ``(N, 3)`` (x, y, yaw); the rows
    are checked by :func:`read_tum_rows`."""
    p = Path(path)
    a, lines = read_tum_rows(p)
    # The yaw is that of the quaternion's direction: divide by its largest component first
    # so that no product overflows (arctan2 does not see the scale); a zero one has none.
    scale = np.max(np.abs(a[:, 4:8]), axis=1)
    if not np.all(scale > 0):
        i = int(np.flatnonzero(~(scale > 0))[0])
        raise DatasetFormatError("expected a rotation quaternion, got (0, 0, 0, 0)", p, lines[i])
    q = a[:, 4:8] / scale[:, None]
    q /= np.linalg.norm(q, axis=1, keepdims=True)  # the formula below wants a unit quaternion
    qx, qy, qz, qw = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return a[:, 0], np.column_stack([a[:, 1], a[:, 2], wrap_angle(yaw)])


def read_tum_matrices(path: str | Path) -> tuple[FloatArray, FloatArray]:
    """Read a TUM file into ``times (N,)`` and SE(3) pose matrices ``(N, 4, 4)`` (the full
    3D poses; :func:`read_tum` projects onto the plane); the rows are checked by
    :func:`read_tum_rows`."""
    p = Path(path)
    a, lines = read_tum_rows(p)
    q = a[:, [7, 4, 5, 6]]  # w, x, y, z
    # Divided by the largest component first, so that the norm of 1e300s does not overflow.
    scale = np.max(np.abs(q), axis=1)
    if not np.all(scale > 0):
        i = int(np.flatnonzero(~(scale > 0))[0])
        raise DatasetFormatError("expected a rotation quaternion, got (0, 0, 0, 0)", p, lines[i])
    q = q / scale[:, None]
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    m = np.zeros((a.shape[0], 4, 4))
    m[:, 0, 0] = 1 - 2 * (y * y + z * z)
    m[:, 0, 1] = 2 * (x * y - z * w)
    m[:, 0, 2] = 2 * (x * z + y * w)
    m[:, 1, 0] = 2 * (x * y + z * w)
    m[:, 1, 1] = 1 - 2 * (x * x + z * z)
    m[:, 1, 2] = 2 * (y * z - x * w)
    m[:, 2, 0] = 2 * (x * z - y * w)
    m[:, 2, 1] = 2 * (y * z + x * w)
    m[:, 2, 2] = 1 - 2 * (x * x + y * y)
    m[:, :3, 3] = a[:, 1:4]
    m[:, 3, 3] = 1.0
    return a[:, 0], m
