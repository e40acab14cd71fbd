"""Landmark maps as CSV: ``id,x,y,cov_xx,cov_xy,cov_yy`` per landmark.

The header line names the columns; positions in metres in the map (world) frame, the
covariance entries in m² (the upper triangle of the symmetric 2×2 covariance). A map without
covariances leaves the three columns empty. :func:`read_landmarks_csv` reads the file back.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, check_unique_ids
from slamkit.errors import DatasetFormatError, ShapeError
from slamkit.maps import LandmarkMap

__all__ = ["LANDMARK_COLUMNS", "format_landmarks_csv", "read_landmarks_csv", "write_landmarks_csv"]

LANDMARK_COLUMNS = ("id", "x", "y", "cov_xx", "cov_xy", "cov_yy")
"""The columns of a landmark CSV file, in order."""


def format_landmarks_csv(landmarks: LandmarkMap, covariances: ArrayLike | None = None) -> str:
    """The text of a landmark CSV file for ``landmarks`` and optional ``covariances (M, 2, 2)``."""
    m = len(landmarks)
    cov = None if covariances is None else as_array(covariances, "covariances", (m, 2, 2))
    lines = [",".join(LANDMARK_COLUMNS)]
    for k in range(m):
        x, y = landmarks.positions[k]
        row = [str(int(landmarks.ids[k])), f"{x:.9g}", f"{y:.9g}"]
        if cov is None:
            row += ["", "", ""]
        else:
            row += [f"{cov[k, 0, 0]:.9g}", f"{0.5 * (cov[k, 0, 1] + cov[k, 1, 0]):.9g}",
                    f"{cov[k, 1, 1]:.9g}"]  # fmt: skip
        lines.append(",".join(row))
    return "\n".join(lines) + "\n"


def write_landmarks_csv(
    path: str | Path, landmarks: LandmarkMap, covariances: ArrayLike | None = None
) -> None:
    """Write a landmark CSV file (see :func:`format_landmarks_csv`)."""
    Path(path).write_text(format_landmarks_csv(landmarks, covariances), encoding="utf-8")


def read_landmarks_csv(path: str | Path) -> tuple[LandmarkMap, FloatArray | None]:
    """Read a landmark CSV file into the map and its covariances ``(M, 2, 2)`` (``None``
    when the covariance columns are empty). Malformed rows raise
    :class:`~slamkit.errors.DatasetFormatError` with the line."""
    p = Path(path)
    lines = p.read_text(encoding="utf-8").splitlines()
    if not lines or tuple(c.strip() for c in lines[0].split(",")) != LANDMARK_COLUMNS:
        raise DatasetFormatError(f"expected the header {','.join(LANDMARK_COLUMNS)}", p, 1)
    ids: list[int] = []
    id_lines: list[int] = []
    rows: list[list[float]] = []
    with_cov: list[bool] = []
    for lineno, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        parts = [c.strip() for c in line.split(",")]
        if len(parts) != len(LANDMARK_COLUMNS):
            raise DatasetFormatError(
                f"expected {len(LANDMARK_COLUMNS)} columns, got {len(parts)}", p, lineno
            )
        try:
            ids.append(int(parts[0]))
            id_lines.append(lineno)
            has_cov = all(parts[3:])
            values = [float(v) for v in parts[1:3]] + (
                [float(v) for v in parts[3:]] if has_cov else [np.nan] * 3
            )
        except ValueError as exc:
            raise DatasetFormatError(f"not a number: {exc}", p, lineno) from None
        with_cov.append(has_cov)
        rows.append(values)
    if not rows:
        raise ShapeError(f"{p}: no landmarks in the file")
    check_unique_ids(ids, id_lines, "landmark id", p)
    a = np.asarray(rows)
    landmarks = LandmarkMap(a[:, :2], np.asarray(ids, dtype=np.int64))
    if not all(with_cov):
        if any(with_cov):
            raise DatasetFormatError("covariances given for some landmarks only", p)
        return landmarks, None
    cov = np.stack(
        [np.stack([a[:, 2], a[:, 3]], axis=-1), np.stack([a[:, 3], a[:, 4]], axis=-1)], axis=-2
    )
    return landmarks, cov
