"""The relation metric over time: translational and rotational error of each scored relation
(:class:`slamkit.eval.RelationError`) against its first stamp ``t1``, drawn on given axes."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes

from slamkit.errors import ShapeError
from slamkit.eval.relations import RelationError

__all__ = ["plot_relation_errors"]


def plot_relation_errors(
    axes: Sequence[Axes],
    scores: RelationError,
    *,
    t0: float | None = None,
    color: str = "tab:blue",
) -> list[list[Artist]]:
    """Draw the translational [m] and rotational [deg] errors of the scored relations over
    ``t1 − t0`` [s] on two axes (``t0``: the first scored ``t1`` unless given; the benchmark's
    stamps are Unix times), as dots with the mean as a dashed line. Returns one list per
    axis, ``[dots, mean line]``."""
    if len(axes) != 2:
        raise ShapeError(f"axes: expected 2 axes (translation, rotation), got {len(axes)}")
    origin = float(np.min(scores.t1)) if t0 is None else float(t0)
    t = scores.t1 - origin
    drawn: list[list[Artist]] = []
    series = (
        (scores.translation_errors, scores.translation_mean, "translational error [m]", "m"),
        (scores.rotation_errors_deg, scores.rotation_mean_deg, "rotational error [deg]", "°"),
    )
    for ax, (values, mean, ylabel, unit) in zip(axes, series, strict=True):
        (dots,) = ax.plot(t, values, ".", ms=2.5, color=color, label="relation")
        line = ax.axhline(mean, color="black", ls="--", lw=1.0, label=f"mean {mean:.3g} {unit}")
        ax.set_ylabel(ylabel)
        ax.legend(loc="upper right", fontsize="small")
        drawn.append([dots, line])
    axes[-1].set_xlabel(f"t1 − {origin:.3f} [s]")
    return drawn
