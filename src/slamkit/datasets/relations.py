"""Reference relations: the ground truth of the Freiburg 2D laser SLAM benchmark.

A relation ``(t1, t2, δ)`` says where the robot was at time ``t2`` in its own frame at time
``t1``: ``δ = x(t1)⁻¹ ⊕ x(t2)`` as ``(x, y, yaw)`` (metres, radians). The benchmark's authors
verified each relation by hand (Kümmerle et al., Autonomous Robots 27(4), 2009), so a data set
can be scored without a global reference trajectory: see :mod:`slamkit.eval.relations`.

File format (``*.relations``), one relation per line, white space separated::

    t1 t2 x y z roll pitch yaw

``z``, ``roll`` and ``pitch`` are 0 in the 2D files; a line where they are not is refused (a
3D relation scored as 2D would be silently wrong). Every stamp in the benchmark's files is the
time stamp of one laser scan of the log.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from slamkit._validation import FloatArray, as_array
from slamkit.datasets.text import read_table
from slamkit.errors import DatasetFormatError, InputError

__all__ = ["Relations", "read_relations"]

#: ``z``, ``roll`` and ``pitch`` above this magnitude make a relation 3D (the benchmark's
#: files hold exact zeros).
PLANAR_TOLERANCE = 1e-9


@dataclass(frozen=True, eq=False)
class Relations:
    """``n`` relations: stamps ``t1 (n,)``, ``t2 (n,)`` and the pose of ``t2`` in the frame
    of ``t1``, ``deltas (n, 3)`` as ``(x, y, yaw)``. ``source`` names the file they came
    from (for messages), if any."""

    t1: FloatArray
    t2: FloatArray
    deltas: FloatArray
    source: str = ""

    def __post_init__(self) -> None:
        t1 = as_array(self.t1, "relations t1", (None,))
        t2 = as_array(self.t2, "relations t2", (t1.size,))
        deltas = as_array(self.deltas, "relations deltas", (t1.size, 3))
        if t1.size == 0:
            raise InputError("relations: expected at least one relation, got none")
        object.__setattr__(self, "t1", t1)
        object.__setattr__(self, "t2", t2)
        object.__setattr__(self, "deltas", deltas)

    def __len__(self) -> int:
        return int(self.t1.size)

    @property
    def stamps(self) -> FloatArray:
        """Every distinct stamp the relations refer to, sorted."""
        return np.unique(np.concatenate([self.t1, self.t2]))

    def until(self, t_end: float) -> Relations | None:
        """The relations whose two stamps are at most ``t_end`` [s] (a data set cut there);
        None when no relation is left."""
        keep = (self.t1 <= t_end) & (self.t2 <= t_end)
        if not keep.any():
            return None
        return Relations(self.t1[keep], self.t2[keep], self.deltas[keep], source=self.source)


def read_relations(path: str | Path) -> Relations:
    """Read a ``*.relations`` file (plain or ``.gz``); a malformed line, a non-zero ``z``,
    roll or pitch, or an empty file raises :class:`~slamkit.errors.DatasetFormatError`
    naming the file and the line."""
    p = Path(path)
    table = read_table(p, 8)
    if len(table) == 0:
        raise DatasetFormatError(
            "no relations in the file (expected 't1 t2 x y z roll pitch yaw')", p
        )
    values = table.values
    off_plane = np.abs(values[:, [4, 5, 6]]).max(axis=1) > PLANAR_TOLERANCE
    if np.any(off_plane):
        row = int(np.argmax(off_plane))
        raise DatasetFormatError(
            "a 3D relation (z, roll or pitch not 0); expected a planar relation",
            p,
            int(table.line_numbers[row]),
        )
    return Relations(values[:, 0], values[:, 1], values[:, [2, 3, 7]], source=str(p))
