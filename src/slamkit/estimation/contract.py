"""The contract between the runner and every estimator.

An estimator is built from ``(dataset, config, rng)``, is fed the dataset's events one by one
through :meth:`Estimator.handle`, reports its current pose estimate through
:meth:`Estimator.estimate` after each time stamp, and hands back its map and diagnostics from
:meth:`Estimator.finish`. The filters themselves are written as pure functions
(``predict(belief, ...) -> belief``); an estimator is the thin stateful shell around them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, Event
from slamkit.errors import ConvergenceError, InputError, NonFiniteError, ShapeError
from slamkit.maps import LandmarkMap, OccupancyGrid
from slamkit.optim.data import GraphData

__all__ = [
    "Estimator",
    "EstimatorOutput",
    "Frame",
    "InnovationLog",
    "LandmarkEstimate",
    "LandmarkIds",
    "LandmarkView",
    "ParticleSnapshot",
    "ParticleView",
    "PoseEstimate",
    "RunWarning",
    "SmoothedTrajectory",
    "SnapshotSchedule",
    "StepClock",
]


@dataclass(frozen=True)
class PoseEstimate:
    """The current pose ``(3,)`` and, for Gaussian estimators, its covariance ``(3, 3)``."""

    pose: FloatArray
    cov: FloatArray | None = None


@dataclass(frozen=True)
class LandmarkEstimate:
    """An estimated landmark map and, where known, each landmark's covariance ``(M, 2, 2)``."""

    landmarks: LandmarkMap
    covariances: FloatArray | None = None


@dataclass(frozen=True)
class InnovationLog:
    """Every measurement update of a Gaussian filter: when, which landmark, the normalised
    innovation squared ``νᵀ S⁻¹ ν`` and its degrees of freedom — the raw material of NIS
    consistency checks on data without a true trajectory."""

    times: FloatArray
    nis: FloatArray
    dof: NDArray[np.int64]
    landmark_ids: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.times.size)


@dataclass(frozen=True)
class ParticleSnapshot:
    """A particle set ``(P, 3)`` with normalised weights ``(P,)`` at time ``t`` (for plots)."""

    t: float
    particles: FloatArray
    weights: FloatArray


class SnapshotSchedule:
    """When a particle filter keeps a :class:`ParticleSnapshot`: after every ``every``-th
    measurement update (0: never) and at the first update at or after each of ``times``."""

    def __init__(self, every: int, times: Iterable[float]) -> None:
        self.every = int(every)
        self._times = sorted(float(t) for t in times)

    def due(self, t: float, updates: int) -> bool:
        """Whether the update number ``updates``, at time ``t``, is to be kept."""
        due = self.every > 0 and updates % self.every == 0
        while self._times and self._times[0] <= t:
            self._times.pop(0)
            due = True
        return due

    @property
    def pending(self) -> bool:
        """Whether requested times are still ahead."""
        return bool(self._times)


class SpreadSnapshots:
    """``n`` snapshots spread over a run whose length is not known in advance, chosen
    causally: every ``stride``-th measurement update is kept (the stride starting at 1);
    when more than ``8n`` are held, those off the doubled stride are dropped, so at most
    ``8n + 1`` copies are ever held and the kept ones are never further apart than
    ``1/(4n)`` of the run so far. :meth:`pick` then chooses ``n``, evenly spaced in update
    count, the first and the final state included."""

    def __init__(self, n: int) -> None:
        self.n = int(n)
        self.stride = 1
        self._kept: list[tuple[int, ParticleSnapshot]] = []

    def offer(self, updates: int, make: Callable[[], ParticleSnapshot]) -> None:
        """Keep ``make()`` as the state after update number ``updates`` (0: the start) if it
        falls on the stride."""
        if self.n <= 0 or updates % self.stride:
            return
        self._kept.append((updates, make()))
        if len(self._kept) > 8 * self.n:
            self.stride *= 2
            first = self._kept[0]
            self._kept = [first] + [k for k in self._kept[1:] if k[0] % self.stride == 0]

    @property
    def held(self) -> int:
        """How many copies are held now."""
        return len(self._kept)

    def pick(self, final: ParticleSnapshot | None = None) -> tuple[ParticleSnapshot, ...]:
        """The ``n`` snapshots: the first, ``final`` (the state at the end, when later than
        the last one kept) and between them the kept ones nearest to evenly spaced times."""
        if self.n <= 0:
            return ()
        items = [s for _, s in self._kept]
        if final is not None and (not items or items[-1].t < final.t):
            items.append(final)
        if len(items) <= self.n:
            return tuple(items)
        times = np.array([s.t for s in items])
        targets = np.linspace(times[0], times[-1], self.n)
        nearest = np.abs(times[None, :] - targets[:, None]).argmin(axis=1)
        return tuple(items[i] for i in np.unique(nearest))


@dataclass(frozen=True)
class SmoothedTrajectory:
    """An estimator's final estimate of its whole path (a smoother's, a pose graph's after
    its last optimisation): poses ``(N, 3)`` at increasing ``times (N,)`` [s] that cover
    every time stamp of the stream (and the data set's start time). The runner puts these
    poses, at its recorded times, in :attr:`~slamkit.pipeline.Result.poses` (the online
    estimates go to :attr:`~slamkit.pipeline.Result.online_poses`)."""

    times: FloatArray
    poses: FloatArray

    def __post_init__(self) -> None:
        t = np.asarray(self.times, dtype=np.float64)
        p = np.asarray(self.poses, dtype=np.float64)
        if t.ndim != 1 or p.shape != (t.size, 3):
            raise ShapeError(
                f"smoothed trajectory: expected times (N,) and poses (N, 3), got {t.shape} "
                f"and {p.shape}"
            )
        if not (np.isfinite(t).all() and np.isfinite(p).all()):
            raise NonFiniteError("smoothed trajectory: non-finite times or poses")
        if t.size > 1 and not (np.diff(t) > 0).all():
            raise InputError("smoothed trajectory: times must increase")
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "poses", p)


class LandmarkIds(Enum):
    """How an estimator's landmark ids relate to the data set's (its output says which, so
    that evaluation pairs maps and scores associations correctly)."""

    DATASET = "dataset"
    """The data set's landmark ids: from readings that carry ids, or from a known map."""
    OWN = "own"
    """Numbered by the estimator itself: maps are paired by position, associations up to a
    relabelling."""


@dataclass(frozen=True)
class EstimatorOutput:
    """What an estimator returns at the end besides its trajectory."""

    landmarks: LandmarkEstimate | None = None
    grid: OccupancyGrid | None = None
    diagnostics: dict[str, Any] = field(default_factory=dict)
    """JSON-able numbers and short lists (counts, statistics) merged into ``metrics.json``."""
    innovations: InnovationLog | None = None
    particle_snapshots: tuple[ParticleSnapshot, ...] = ()
    reading_landmarks: NDArray[np.int64] | None = None
    """The data association an estimator chose: the id of the landmark every reading updated
    or started, concatenated over the :class:`~slamkit.datasets.LandmarkReadings` events in
    stream order (``-1``: the reading was not used). Scored against
    ``truth.reading_ids`` by :func:`slamkit.eval.association_scores`."""
    landmark_numbering: LandmarkIds | None = None
    """How the ids of ``landmarks`` and ``reading_landmarks`` relate to the data set's: the
    estimator says (``None``: it has no landmarks)."""
    trajectory: SmoothedTrajectory | None = None
    """The final estimate of the whole path, when the estimator revises its past (a pose
    graph); the runner reports it instead of the online estimates. ``None``: the online
    estimates are the result."""
    graph: GraphData | None = None
    """The pose graph an estimator built and optimised (written as ``graph.g2o`` by
    :func:`slamkit.app.run_job`)."""
    warnings: tuple[RunWarning, ...] = ()
    """What the estimator found that makes its result suspect (printed by ``slamkit run``,
    listed under ``warnings`` in ``metrics.json`` and on the report page)."""


@dataclass(frozen=True)
class RunWarning:
    """One reason to doubt a run's result, found by the estimator itself: ``kind`` a short
    code (``"odometry_glitches"``, ``"track_lost"``, …), ``message`` one line for a person
    saying what, where and how much."""

    kind: str
    message: str

    def as_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "message": self.message}


@dataclass(frozen=True)
class Frame:
    """The estimate at one moment of a run (for animations): the pose and its covariance,
    and what the estimator offers of its map and particles at that moment."""

    t: float
    pose: FloatArray
    cov: FloatArray | None = None
    landmarks: LandmarkEstimate | None = None
    particles: FloatArray | None = None
    """Particle poses ``(P, 3)`` of a particle filter."""


class StepClock:
    """The runner's step numbering inside an estimator — one step per distinct time stamp,
    the first event being step 1 — so that an estimator's own errors name the step the
    runner would (:class:`~slamkit.errors.ConvergenceError` carries it)."""

    def __init__(self) -> None:
        self.step = 0
        self._t: float | None = None

    def tick(self, t: float) -> int:
        """Count the event at time ``t``; the step it belongs to."""
        if self._t is None or t != self._t:
            self.step += 1
            self._t = t
        return self.step

    @property
    def time(self) -> float | None:
        """The time stamp of the event counted last (``None`` before the first)."""
        return self._t

    def stamped(self, exc: ConvergenceError, name: str, t: float) -> ConvergenceError:
        """``exc`` if it already names a step, else a :class:`~slamkit.errors.ConvergenceError`
        ``"{name} at t = {t} s: ..."`` carrying the current step (raise it ``from exc``).

        A method the caller uses in its own ``except`` clause rather than a context manager:
        entering a generator-based context on every event costs as much as a small filter's
        whole prediction step (see ``benchmarks/bench_filters.py``)."""
        if exc.step is not None:
            return exc
        return ConvergenceError(f"{name} at t = {t:g} s: {exc}", step=self.step)


class Estimator(Protocol):
    """What the runner needs of an estimator (see the module docstring).

    An estimator may also offer the views :class:`LandmarkView` (its current map) and
    :class:`ParticleView` (its current particle poses), which feed the frames of an
    animation (:func:`slamkit.pipeline.run` with ``frames``).
    """

    def handle(self, event: Event) -> None: ...

    def estimate(self) -> PoseEstimate: ...

    def finish(self) -> EstimatorOutput: ...


@runtime_checkable
class LandmarkView(Protocol):
    """An estimator that can show its current landmark map (``None``: no map yet)."""

    def landmark_estimate(self) -> LandmarkEstimate | None: ...


@runtime_checkable
class ParticleView(Protocol):
    """A particle filter that can show its current particle poses ``(P, 3)``."""

    def particle_poses(self) -> FloatArray: ...


class EstimatorFactory(Protocol):
    def __call__(self, dataset: Dataset, config: Any, rng: np.random.Generator) -> Estimator: ...
