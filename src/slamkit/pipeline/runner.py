"""The runner: feeds any registered estimator with any data set and collects a Result."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from slamkit import runtime
from slamkit._validation import FloatArray
from slamkit.config import config_to_dict
from slamkit.datasets.stream import Dataset, group_by_time, with_known_poses
from slamkit.errors import ConvergenceError, InputError
from slamkit.estimation.contract import (
    Estimator,
    EstimatorOutput,
    Frame,
    LandmarkView,
    ParticleView,
    PoseEstimate,
)
from slamkit.geometry.pose2 import interpolate_poses
from slamkit.pipeline.registry import EstimatorEntry, get_estimator_entry
from slamkit.pipeline.work import work_measure

__all__ = ["Progress", "Result", "Stage", "run"]

log = logging.getLogger(__name__)

Progress = Callable[[int, int], None]
"""``progress(done, total)`` in units of work (:func:`~slamkit.pipeline.work.work_measure`:
scans, landmark readings or events); called about a hundred times per run."""

Stage = Callable[[str], None]
"""``stage(text)``: a step without a count has begun (the estimator's last step)."""


@dataclass(frozen=True)
class Result:
    """What one run produced: a trajectory (one pose per time stamp of the stream, plus the
    start), its covariances if the estimator has them, per-step timings and the estimator's
    map and diagnostics. ``config`` is the resolved configuration, JSON-able.

    When the estimator returns a final trajectory (:attr:`EstimatorOutput.trajectory`, e.g.
    a particle filter's best path), ``times``/``poses`` are that trajectory, ``covariances``
    is None, and ``step_seconds`` still counts the runner's steps."""

    estimator: str
    dataset: str
    seed: int
    config: dict[str, Any]
    times: FloatArray
    poses: FloatArray
    covariances: FloatArray | None
    step_seconds: FloatArray
    output: EstimatorOutput
    frames: tuple[Frame, ...] = ()
    """Snapshots of the estimate at evenly spaced times (``run(..., frames=N)``)."""
    online_poses: FloatArray | None = None
    """The estimates recorded during the run ``(N, 3)`` when the estimator handed back a
    revised path (:attr:`EstimatorOutput.trajectory`, then :attr:`poses` is that path at
    :attr:`times`); ``None``: :attr:`poses` are the online estimates."""

    @property
    def total_seconds(self) -> float:
        return float(self.step_seconds.sum())

    def __len__(self) -> int:
        return int(self.times.size)


def _record(est: PoseEstimate, step: int) -> tuple[np.ndarray, np.ndarray | None]:
    pose = np.asarray(est.pose, dtype=float)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise ConvergenceError(f"the estimator returned a non-finite pose {pose}", step)
    cov = None if est.cov is None else np.asarray(est.cov, dtype=float)
    if cov is not None and not np.all(np.isfinite(cov)):
        raise ConvergenceError("the estimator's covariance became non-finite", step)
    return pose, cov


def _frame(est: Estimator, t: float, pose: np.ndarray, cov: np.ndarray | None) -> Frame:
    """A snapshot through the views the estimator offers (:class:`LandmarkView`,
    :class:`ParticleView`)."""
    return Frame(
        t,
        pose,
        cov,
        est.landmark_estimate() if isinstance(est, LandmarkView) else None,
        np.array(est.particle_poses(), dtype=float) if isinstance(est, ParticleView) else None,
    )


def run(
    estimator: str | EstimatorEntry,
    dataset: Dataset,
    *,
    config: Mapping[str, Any] | Any | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    frames: int = 0,
    stage: Stage | None = None,
    blas_threads: int | None = None,
) -> Result:
    """Run ``estimator`` (a registered name or entry) over ``dataset``.

    The estimate is recorded at the start and after every group of events that share a time
    stamp. ``seed`` seeds the estimator's own ``np.random.Generator`` (particle filters).
    ``frames > 0`` also keeps about that many :class:`Frame` snapshots (pose, map,
    particles), evenly spaced in time, the last one at the end of the run.

    ``config`` is a mapping (unknown keys rejected) or a config object.

    An estimator that revises its past (a pose graph) hands its final path back as
    :attr:`EstimatorOutput.trajectory`; :attr:`Result.poses` is then that path at the
    recorded times and :attr:`Result.online_poses` the estimates recorded during the run.

    ``blas_threads``: BLAS threads during the run; ``None``, the library's policy
    (:func:`slamkit.runtime.blas_threads`: one thread, unless the environment sets a count).
    """
    with runtime.blas_threads(blas_threads):
        return _run(
            estimator,
            dataset,
            config=config,
            seed=seed,
            progress=progress,
            frames=frames,
            stage=stage,
        )


def _run(
    estimator: str | EstimatorEntry,
    dataset: Dataset,
    *,
    config: Mapping[str, Any] | Any | None,
    seed: int,
    progress: Progress | None,
    frames: int,
    stage: Stage | None,
) -> Result:
    """:func:`run` under its thread policy."""
    if not (isinstance(frames, int) and frames >= 0):
        raise InputError(f"frames: expected an integer >= 0, got {frames!r}")
    entry = get_estimator_entry(estimator) if isinstance(estimator, str) else estimator
    cfg = entry.make_config(config)
    if entry.known_poses and dataset.truth.poses is not None:
        dataset = with_known_poses(dataset)  # mapping with known poses: given in the stream
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    est = entry.create(dataset, cfg, rng)
    setup = time.perf_counter() - t0

    events = dataset.events
    weights = work_measure(entry, dataset).weights
    total = int(weights.sum())
    every = max(1, -(-total // 100))  # ceil: at most ~100 progress calls
    next_report = every
    times: list[float] = []
    poses: list[np.ndarray] = []
    covs: list[np.ndarray | None] = []
    seconds: list[float] = []

    pose, cov = _record(est.estimate(), 0)
    first_t = events[0].t if events else dataset.start_time
    snapshots: list[Frame] = []
    frame_dt = (events[-1].t - first_t) / frames if frames and events else 0.0
    last_slot = -1  # frames are taken on the time grid first_t + k frame_dt
    if dataset.start_time < first_t:
        times.append(dataset.start_time)
        poses.append(pose)
        covs.append(cov)
        seconds.append(setup)
        setup = 0.0
    done = 0  # units of work
    seen = 0  # events
    log.debug("running %s on %s (%d events)", entry.name, dataset.name, len(events))
    for step, (t, group) in enumerate(group_by_time(events), start=1):
        tic = time.perf_counter()
        for ev in group:
            est.handle(ev)
        pose, cov = _record(est.estimate(), step)
        seconds.append(time.perf_counter() - tic + setup)
        setup = 0.0
        times.append(t)
        poses.append(pose)
        covs.append(cov)
        slot = int((t - first_t) // frame_dt) if frame_dt > 0 else last_slot + 1
        if frames and (slot > last_slot or seen + len(group) == len(events)):
            snapshots.append(_frame(est, t, pose, cov))
            last_slot = slot
        done += int(weights[seen : seen + len(group)].sum())
        seen += len(group)
        if progress is not None and done >= next_report:
            progress(done, total)
            next_report = done + every
    if progress is not None:
        progress(total, total)
    if stage is not None:
        stage(f"finishing {entry.name}")
    output = est.finish()
    have_cov = all(c is not None for c in covs) and bool(covs)
    recorded = np.asarray(poses, dtype=float).reshape(-1, 3)
    final, online = recorded, None
    if output.trajectory is not None and times:
        # A revised path (a pose graph after its last optimisation) replaces the online
        # estimates at the recorded times; the online ones are kept beside it.
        final = interpolate_poses(output.trajectory.times, output.trajectory.poses, times)
        online = recorded
    return Result(
        estimator=entry.name,
        dataset=dataset.name,
        seed=seed,
        config=config_to_dict(cfg),
        times=np.asarray(times, dtype=float),
        poses=final,
        # online covariances do not describe a revised path
        covariances=np.asarray(covs, dtype=float) if have_cov and online is None else None,
        step_seconds=np.asarray(seconds, dtype=float),
        output=output,
        frames=tuple(snapshots),
        online_poses=online,
    )
