"""The request and report of ``slamkit landmark-graph`` (:mod:`slamkit.app.landmark_graph`),
shared with its fixed-lag variant (:mod:`slamkit.app.landmark_smoother`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["LandmarkGraphReport", "LandmarkGraphRequest"]


@dataclass(frozen=True)
class LandmarkGraphRequest:
    """The options of one ``slamkit landmark-graph`` run."""

    data: str
    """A registered landmark data set (``victoria-park``, ``landmark-loop``, …)."""
    out_dir: Path
    """The output folder (written atomically; an existing non-empty one needs ``overwrite``)."""
    gps: bool = True
    """Fuse the data set's GPS track."""
    weighting: str = "gate"
    """How fixes are re-weighted: ``none``, ``huber``, ``cauchy``, ``geman_mcclure``,
    ``dcs`` or ``gate`` (:class:`~slamkit.optim.gps.GpsWeighting`)."""
    width: float | None = None
    """Kernel width or gate bound; None: the weighting's default (gate 9.21, kernels as
    :data:`~slamkit.optim.robust.DEFAULT_WIDTHS`)."""
    gps_sigma: float = 1.0
    """Standard deviation of a fix per axis [m]."""
    holdout_every: int = 10
    """Hold every k-th fix out of the graph and score on those (0: fuse all, no score)."""
    max_duration_s: float | None = None
    """Use only the first this many seconds of the data (all: None)."""
    seed: int = 0
    """Seed of a simulated data set."""
    window: int | None = None
    """Smooth the graph (its GPS left out, scoring only) over this many nodes instead of
    solving it in batch and fusing the fixes (:mod:`slamkit.app.landmark_smoother`)."""
    plots: bool = True
    overwrite: bool = False
    data_root: Path | None = None
    hierarchical: int | None = None
    """Fuse the fixes hierarchically, local maps of this many poses joined at a top level of
    their base frames (:mod:`slamkit.slam.landmark_graph.hierarchical`), instead of in one
    flat graph."""


@dataclass(frozen=True, eq=False)
class LandmarkGraphReport:
    """What :func:`landmark_graph_job` wrote and measured."""

    out_dir: Path
    files: tuple[str, ...]
    metrics: dict[str, Any]
