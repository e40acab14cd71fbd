"""Typed scores of one run: what :func:`slamkit.pipeline.evaluate.evaluate` measures, as
frozen records, each metric either its result type or :class:`Skipped` with the reason it
does not apply (a path shorter than the RPE distance, a robot that never moved, maps without
common landmarks). JSON only at the io boundary: :meth:`RunScores.as_dict` gives the
``metrics.json`` form."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any, Literal, Protocol

from slamkit.eval.association import AssociationScores
from slamkit.eval.convergence import ConvergenceReport
from slamkit.eval.gps import GpsError
from slamkit.eval.innovations import NisSummary
from slamkit.eval.landmarks import LandmarkError
from slamkit.eval.relations import RelationError
from slamkit.eval.signals import SelfSignals
from slamkit.eval.trajectory import RelativeError, TrajectoryError
from slamkit.eval.verdict import Verdict, verdict

__all__ = [
    "NeesSummary",
    "RunScores",
    "RunTime",
    "Skipped",
]


@dataclass(frozen=True)
class Skipped:
    """A metric that does not apply to this run, and why."""

    reason: str

    def as_dict(self) -> dict[str, str]:
        return {"skipped": self.reason}


@dataclass(frozen=True)
class NeesSummary:
    """NEES of the pose against the true trajectory over the steps whose covariance is
    regular, with the two-sided 95 % χ²(3) band of one step."""

    mean: float
    dof: int
    band_95: tuple[float, float]
    fraction_in_band: float
    steps: int

    def as_dict(self) -> dict[str, Any]:
        return {
            "mean": self.mean,
            "dof": self.dof,
            "band_95": list(self.band_95),
            "fraction_in_band": self.fraction_in_band,
            "steps": self.steps,
        }


@dataclass(frozen=True)
class RunTime:
    """Wall-clock seconds of the run: all steps, and the mean and largest step."""

    total_seconds: float
    mean_step_seconds: float
    max_step_seconds: float

    def as_dict(self) -> dict[str, float]:
        return {
            "total_seconds": self.total_seconds,
            "mean_step_seconds": self.mean_step_seconds,
            "max_step_seconds": self.max_step_seconds,
        }


class Finding(Protocol):
    """A warning about a run: the consistency monitor's
    (:class:`~slamkit.eval.monitor.ConsistencyWarning`) or an
    estimator's own (:class:`slamkit.estimation.contract.RunWarning`)."""

    @property
    def message(self) -> str:
        """One line for a person."""
        ...

    def as_dict(self) -> dict[str, Any]:
        """Plain values for ``metrics.json``, ``message`` among them."""
        ...


@dataclass(frozen=True)
class RunScores:
    """Every score of one run. ``None``: the data set has nothing to score it against (no
    true trajectory, no GPS, no true landmarks, ...); :class:`Skipped`: it has, but the
    metric does not apply to this run."""

    estimator: str
    dataset: str
    seed: int
    steps: int
    runtime: RunTime
    diagnostics: dict[str, Any] = field(default_factory=dict)
    """The estimator's own JSON-able counts and statistics (``EstimatorOutput``)."""
    matched_steps: int | None = None
    ate: TrajectoryError | Skipped | None = None
    ate_unaligned: TrajectoryError | Skipped | None = None
    rpe_1_step: RelativeError | Skipped | None = None
    rpe_10_m: RelativeError | Skipped | None = None
    final_position_error: float | None = None
    convergence: ConvergenceReport | Skipped | None = None
    nees: NeesSummary | None = None
    gps: GpsError | Skipped | None = None
    nis: NisSummary | Skipped | None = None
    landmarks_matched_by: Literal["id", "position"] | None = None
    landmarks: LandmarkError | Skipped | None = None
    association: AssociationScores | Skipped | None = None
    relations: RelationError | Skipped | None = None
    """The relation metric against the data set's reference relations
    (:func:`slamkit.eval.relation_errors`); skipped when the run covers none of them."""
    signals: SelfSignals | None = None
    """What the estimator knows of itself, with or without ground truth (keyframes,
    closures, the graph's normalised χ², scans matched, N_eff, NIS, landmark counts:
    :mod:`slamkit.eval.signals`); None when its diagnostics hold none of them."""
    warnings: tuple[Finding, ...] = ()
    """The consistency monitor's findings (:mod:`slamkit.eval.monitor`): NEES or NIS far
    outside its χ² band over a window; empty for a run that looks consistent (or has
    neither statistic). ``metrics.json`` always holds the list."""

    def as_dict(self) -> dict[str, Any]:
        """The ``metrics.json`` form, in field order: plain values, records through their
        ``as_dict``, metrics that do not apply as ``{"skipped": reason}``, those without a
        reference (``None``) left out."""
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, tuple):  # a list of records
                out[f.name] = [v.as_dict() for v in value]
            elif value is not None:
                out[f.name] = value.as_dict() if hasattr(value, "as_dict") else value
        out["verdict"] = self.verdict.as_dict()
        return out

    @property
    def verdict(self) -> Verdict:
        """The run's one-line verdict from its findings (:mod:`slamkit.eval.verdict`)."""
        return verdict(self.warnings)
