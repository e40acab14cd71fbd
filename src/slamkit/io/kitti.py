"""KITTI trajectory text files: the first three rows of the 4×4 pose matrix, row-major, 12
numbers per line (``r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz``), no time stamps.

SE(2) poses are written as planar SE(3) poses (z = 0, rotation about z), as for TUM files;
:func:`read_kitti` projects back onto the plane (the yaw of the rotation),
:func:`read_kitti_matrices` keeps the full SE(3) poses. The times go to a separate file, one
stamp a line, as the KITTI odometry benchmark's ``times.txt`` (:func:`write_kitti` writes it
when given a path).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.datasets.text import text_lines
from slamkit.errors import DatasetFormatError, ShapeError
from slamkit.geometry import wrap_angle

__all__ = ["format_kitti", "read_kitti", "read_kitti_matrices", "write_kitti"]


def format_kitti(poses: ArrayLike) -> str:
    """The text of a KITTI file for SE(2) ``poses (N, 3)``."""
    p = as_array(poses, "poses", (None, 3))
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    zero, one = np.zeros_like(c), np.ones_like(c)
    cols = np.column_stack([c, 0.0 - s, zero, p[:, 0], s, c, zero, p[:, 1], zero, zero, one, zero])
    return "".join(" ".join(f"{v:.9g}" for v in row) + "\n" for row in cols)


def write_kitti(
    path: str | Path, poses: ArrayLike, *, times: ArrayLike | None = None,
    times_path: str | Path | None = None,
) -> None:  # fmt: skip
    """Write a KITTI file (see :func:`format_kitti`); with ``times`` and ``times_path`` also
    the stamps, one a line."""
    Path(path).write_text(format_kitti(poses), encoding="utf-8")
    if times is not None and times_path is not None:
        t = as_array(times, "times", (None,))
        Path(times_path).write_text("".join(f"{v:.16g}\n" for v in t), encoding="utf-8")


def read_kitti_matrices(path: str | Path) -> FloatArray:
    """Read a KITTI file into SE(3) pose matrices ``(N, 4, 4)``."""
    p = Path(path)
    rows: list[list[float]] = []
    for lineno, line in enumerate(text_lines(p.read_text(encoding="utf-8")), start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        parts = text.split()
        if len(parts) != 12:
            raise DatasetFormatError(f"expected 12 numbers, got {len(parts)}", p, lineno)
        try:
            rows.append([float(v) for v in parts])
        except ValueError as exc:
            raise DatasetFormatError(f"not a number: {exc}", p, lineno) from None
    if not rows:
        raise ShapeError(f"{p}: no poses in the file")
    a = np.asarray(rows).reshape(-1, 3, 4)
    out = np.zeros((a.shape[0], 4, 4))
    out[:, :3, :] = a
    out[:, 3, 3] = 1.0
    return out


def read_kitti(path: str | Path) -> FloatArray:
    """Read a KITTI file into SE(2) poses ``(N, 3)`` (x, y, yaw)."""
    m = read_kitti_matrices(path)
    yaw = np.arctan2(m[:, 1, 0], m[:, 0, 0])
    return np.column_stack([m[:, 0, 3], m[:, 1, 3], wrap_angle(yaw)])
