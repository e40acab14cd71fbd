"""The leave-out split of a GPS track: which fixes an estimator is not given, so that it can
be scored on them (:func:`slamkit.eval.gps_holdout.holdout_gps_error`). One rule for every
user — the loaders that put fixes into the stream (Victoria Park's ``gps_holdout_every``)
and the landmark graph (:class:`~slamkit.slam.landmark_graph.GpsFixes`) — so that a filter
and a graph leave out, and are scored on, the same fixes."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["holdout_mask"]


def holdout_mask(n: int, every: int) -> NDArray[np.bool_]:
    """Mask ``(n,)`` of the fixes held out: every ``every``-th (the 10th, 20th, … for
    ``every = 10``, i.e. indices ``every − 1``, ``2 every − 1``, …); none for ``every = 0``."""
    idx = np.arange(n)
    return (idx % every == every - 1) if every else np.zeros(n, dtype=bool)
