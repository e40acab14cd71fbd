"""A fixed-lag (sliding-window) smoother for 2D pose graphs: the last ``window`` poses are the
unknowns, older poses are marginalised into a prior on the poses they were tied to, and every
step costs the same however long the run.

The window after pose 9 with ``window = 4`` (``━`` edges, ``┄`` loop closures)::

      marginalised (their estimates are the output)     the window: X6 … X9, the unknowns
   X0 ━ X1 ━ X2 ━ X3 ━ X4 ━ X5 ━━[ marginal prior on X6, X8 ]━━ X6 ━ X7 ━ X8 ━ X9
   ▲         ┆                   ┆                                         ┆
   anchor    └┄┄┄ dropped ┄┄┄┄┄┄┄┼┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┄┘ (X1 is gone)
                                 X5 ┄ X8 folded into the prior when X5 left

**A step** (:meth:`FixedLagSmoother.update`, one pose and the edges whose later end it is):

1. the new pose gets its guess (given, or the first edge to a pose in the window, or to the
   anchor, composed with that pose's current estimate; a prior edge gives its measurement);
2. its edges join the window; an edge to a pose already marginalised out is **dropped** and
   counted (see below);
3. Gauss-Newton on the window poses, over the window's edges and the marginal prior
   (``max_iterations`` at most, stopping once ``max |δ| ≤ step_tolerance``), from the
   previous step's estimate;
4. if the window holds more than ``window`` poses, the oldest is marginalised
   (:mod:`slamkit.optim.marginal_prior`: the Schur complement of every factor touching it,
   the old prior included, linearised at the current estimate) and its current estimate
   becomes its **online estimate**, the smoother's output for that pose.

The system of a step has ``3 · window`` unknowns and the prior at most as many, whatever the
length of the run: a step's cost depends on the window and on how many edges its poses have,
not on the step number (dense Cholesky of the window system; ``docs/estimators/optim.md``
has the measured times).

**Edges to marginalised poses are dropped, not folded in.** A loop closure from a new pose
``j`` to a pose ``i`` that has left the window would need the joint Gaussian of ``X_i`` and
the window, which marginalisation discarded (only the window's marginal is kept). Treating
``X_i`` as fixed at its online estimate would turn the edge into a unary prior on ``X_j``
and use the information behind ``X_i`` twice (its estimate already came from the edges the
window's prior summarises): an overconfident, biased estimate. So such edges are dropped and
counted (:attr:`FixedLagResult.dropped_edges`, with their file lines); a window long enough
to hold the loop is the remedy. Edges to the anchor (below) are always used: it is known
exactly.

**Gauge.** As in batch, the first pose is the anchor, held fixed at its guess, unless its own
step carries a ``se2_prior`` edge on it; then every pose is free. (A prior that first arrives
on a later pose acts as an ordinary factor and the anchor stays; batch would free every
pose.)

**Equal to batch when the window holds the whole run.** Nothing is marginalised, the window
is the whole graph, and :meth:`FixedLagSmoother.finish` iterates Gauss-Newton on it to
``FINISH_STEP_TOLERANCE``: the batch optimum (the tests check it).

Time has no seconds here: graph files carry no stamps, so the window is counted in poses.
Landmarks and 3D graphs are not handled.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from slamkit import runtime
from slamkit.errors import ConfigError, ConvergenceError, GeometryError, InputError
from slamkit.geometry import pose2
from slamkit.optim import factors
from slamkit.optim.data import EdgeSet, FloatArray, GraphData, IntArray
from slamkit.optim.marginal_prior import MarginalPrior, schur_prior
from slamkit.optim.updates import (
    UPDATE_KINDS,
    check_guesses,
    check_update_edges,
    edge_name,
    time_ordered_updates,
)
from slamkit.optim.window import window_normal_equations, window_terms

__all__ = [
    "FINISH_MAX_ITERATIONS",
    "FINISH_STEP_TOLERANCE",
    "FixedLagConfig",
    "FixedLagResult",
    "FixedLagSmoother",
    "StepInfo",
    "smooth_fixed_lag",
]

FINISH_MAX_ITERATIONS = 100
"""Gauss-Newton iterations of :meth:`FixedLagSmoother.finish` at most."""
FINISH_STEP_TOLERANCE = 1e-10
""":meth:`FixedLagSmoother.finish` stops after a step with ``max |δ|`` at most this."""
MAX_REPORTED_DROPS = 20
"""File lines of dropped edges kept in :attr:`FixedLagResult.dropped_lines`."""


@dataclass(frozen=True)
class FixedLagConfig:
    """Settings of :class:`FixedLagSmoother`; steps ``δ`` are SE(2) tangent vectors
    ``(δx, δy, δθ)`` in metres and radians."""

    window: int = 50
    """Poses kept as unknowns; the oldest is marginalised when a step brings one more."""
    max_iterations: int = 3
    """Gauss-Newton iterations of a step at most (each relinearises the window's edges)."""
    step_tolerance: float = 1e-6
    """A step stops after a Gauss-Newton iteration with ``max |δ| ≤ step_tolerance``."""

    def __post_init__(self) -> None:
        for name in ("window", "max_iterations"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1, got {v!r}")
        if not (np.isfinite(self.step_tolerance) and self.step_tolerance >= 0):
            raise ConfigError(
                f"step_tolerance: expected a finite number >= 0, got {self.step_tolerance!r}"
            )


@dataclass(frozen=True)
class StepInfo:
    """What one :meth:`FixedLagSmoother.update` did."""

    step: int  # 1-based
    pose_id: int
    window_poses: int  # unknowns after the step
    prior_poses: int  # poses the marginal prior is on after the step
    iterations: int  # Gauss-Newton iterations run
    step_norm: float  # max |δ| of the last iteration
    dropped: int  # edges of this step to poses already marginalised out
    left_id: int | None  # the pose marginalised at this step
    seconds: float


@dataclass(frozen=True)
class FixedLagResult:
    """The smoother's output after :meth:`FixedLagSmoother.finish`; rows of the per-pose
    arrays follow ``pose_ids`` (arrival order)."""

    pose_ids: IntArray
    poses: FloatArray  # each pose's online estimate as it left; window poses: the final window
    initial_poses: FloatArray  # the guess each pose arrived with
    left_at_step: IntArray  # step at which the pose left the window; 0: final window or anchor
    window_ids: IntArray  # the final window (anchor excluded)
    window_poses: FloatArray
    window_chi2: float  # the window's edges and prior at the final window estimate
    converged: bool  # finish() met FINISH_STEP_TOLERANCE
    window: int
    steps: int
    step_seconds: FloatArray  # (steps,) wall time of each update
    step_iterations: IntArray  # (steps,)
    dropped_edges: int
    dropped_lines: IntArray  # file lines of the first MAX_REPORTED_DROPS dropped edges
    max_prior_poses: int
    anchored_first: bool
    finish_seconds: float


class FixedLagSmoother:
    """A 2D pose graph smoothed over a sliding window (module docstring).

    ``update(pose_id, edges, initial_pose)`` adds one pose and its edges and returns a
    :class:`StepInfo`; ``window_estimate()`` gives the window; ``prior()`` the marginal prior;
    ``finish()`` converges the last window and returns a :class:`FixedLagResult`.
    """

    def __init__(self, config: FixedLagConfig | None = None) -> None:
        self.config = config if config is not None else FixedLagConfig()
        self._wid = np.zeros(0, dtype=np.int64)  # window pose ids, increasing
        self._X = np.zeros((0, 3))  # their estimates
        self._anchor: tuple[int, FloatArray] | None = None
        self._ea = np.zeros(0, dtype=np.int64)  # window edges: id of the first pose
        self._eb = np.zeros(0, dtype=np.int64)  # id of the second pose, -1 for priors
        self._ez = np.zeros((0, 3))
        self._eU = np.zeros((0, 3, 3))  # U with Uᵀ U = Ω
        self._prior: MarginalPrior | None = None
        self._seen: set[int] = set()
        self._last_id: int | None = None
        self._ids: list[int] = []
        self._out: list[FloatArray] = []  # online estimate (or the guess until it leaves)
        self._guess: list[FloatArray] = []
        self._left: list[int] = []
        self._row: dict[int, int] = {}  # pose id → row of the per-pose lists
        self._steps = 0
        self._seconds: list[float] = []
        self._iterations: list[int] = []
        self._dropped = 0
        self._dropped_lines: list[int] = []
        self._max_prior = 0

    # ------------------------------------------------------------------ accessors
    def window_estimate(self) -> tuple[IntArray, FloatArray]:
        """``(pose_ids, poses)`` of the window's unknowns (copies)."""
        return self._wid.copy(), self._X.copy()

    def prior(self) -> MarginalPrior | None:
        """The marginal prior on the window (``None`` before the first marginalisation)."""
        return self._prior

    # ------------------------------------------------------------------ a step
    def update(
        self,
        pose_id: int,
        edges: Sequence[EdgeSet] = (),
        initial_pose: FloatArray | None = None,
    ) -> StepInfo:
        """Add pose ``pose_id`` (above every id so far) with ``edges`` (their ends among the
        poses added so far and this one) and run one step (module docstring). Raises
        :class:`~slamkit.errors.InputError` subclasses naming the pose or edge."""
        t0 = time.perf_counter()
        pid = self._check_id(pose_id)
        guess = check_guesses(
            None if initial_pose is None else np.reshape(initial_pose, (1, 3)),
            np.array([pid], dtype=np.int64),
        )
        checked = [check_update_edges(es) for es in edges]
        kept, dropped_lines = self._sort_edges(pid, checked)
        X_new = self._initial_guess(pid, kept, None if guess is None else guess[0])
        dropped = len(dropped_lines)
        self._dropped += dropped
        room = MAX_REPORTED_DROPS - len(self._dropped_lines)
        self._dropped_lines.extend(dropped_lines[: max(room, 0)])
        first = self._last_id is None
        self._seen.add(pid)
        self._last_id = pid
        self._row[pid] = len(self._ids)
        self._ids.append(pid)
        self._guess.append(X_new)
        self._out.append(X_new)
        self._left.append(0)
        self._steps += 1
        if first and not any(es.kind == "se2_prior" and (es.i == pid).any() for es, _ in kept):
            self._anchor = (pid, X_new)
        else:
            self._wid = np.append(self._wid, pid)
            self._X = np.vstack([self._X, X_new[None, :]])
        for es, U in kept:
            self._ea = np.concatenate([self._ea, es.i])
            self._eb = np.concatenate([self._eb, es.j if es.kind == "se2" else -np.ones_like(es.i)])
            self._ez = np.concatenate([self._ez, es.measurement])
            self._eU = np.concatenate([self._eU, U])
        iterations, step = self._gauss_newton(
            self.config.max_iterations, self.config.step_tolerance
        )
        left = None
        if self._wid.shape[0] > self.config.window:
            left = self._marginalize_oldest()
        seconds = time.perf_counter() - t0
        self._seconds.append(seconds)
        self._iterations.append(iterations)
        n_prior = 0 if self._prior is None else int(self._prior.pose_ids.shape[0])
        self._max_prior = max(self._max_prior, n_prior)
        return StepInfo(
            self._steps, pid, int(self._wid.shape[0]), n_prior, iterations, step, dropped,
            left, seconds,
        )  # fmt: skip

    def finish(self) -> FixedLagResult:
        """Converge the last window (Gauss-Newton to ``FINISH_STEP_TOLERANCE``) and return
        the result: every marginalised pose at its online estimate, the window's at the
        final estimate."""
        if not self._ids:
            raise InputError("the smoother has no poses: call update() first")
        t0 = time.perf_counter()
        _, step = self._gauss_newton(FINISH_MAX_ITERATIONS, FINISH_STEP_TOLERANCE)
        converged = step <= FINISH_STEP_TOLERANCE
        for pid, x in zip(self._wid.tolist(), self._X, strict=True):
            self._out[self._row[pid]] = x.copy()
        chi2 = self._chi2()
        finish_seconds = time.perf_counter() - t0
        return FixedLagResult(
            pose_ids=np.array(self._ids, dtype=np.int64),
            poses=np.array(self._out).reshape(-1, 3),
            initial_poses=np.array(self._guess).reshape(-1, 3),
            left_at_step=np.array(self._left, dtype=np.int64),
            window_ids=self._wid.copy(),
            window_poses=self._X.copy(),
            window_chi2=chi2,
            converged=converged,
            window=self.config.window,
            steps=self._steps,
            step_seconds=np.array(self._seconds),
            step_iterations=np.array(self._iterations, dtype=np.int64),
            dropped_edges=self._dropped,
            dropped_lines=np.array(self._dropped_lines, dtype=np.int64),
            max_prior_poses=self._max_prior,
            anchored_first=self._anchor is not None,
            finish_seconds=finish_seconds,
        )

    # ------------------------------------------------------------------ input
    def _check_id(self, pose_id: int) -> int:
        if isinstance(pose_id, bool) or not isinstance(pose_id, (int, np.integer)):
            raise InputError(f"pose id: expected an integer, got {pose_id!r}")
        pid = int(pose_id)
        if self._last_id is not None and pid <= self._last_id:
            raise InputError(
                f"pose {pid} arrives after pose {self._last_id}: pose ids must increase in "
                "time order"
            )
        return pid

    def _sort_edges(
        self, pid: int, checked: list[tuple[EdgeSet, FloatArray]]
    ) -> tuple[list[tuple[EdgeSet, FloatArray]], list[int]]:
        """The edges (or parts of edge sets) to keep, and the file lines (0: none) of those
        dropped because an end has been marginalised; an end never seen, or an edge from a
        pose to itself, is an error naming the edge."""
        usable = set(self._wid.tolist()) | {pid}
        if self._anchor is not None:
            usable.add(self._anchor[0])
        kept: list[tuple[EdgeSet, FloatArray]] = []
        dropped: list[int] = []
        for es, U in checked:
            keep = np.ones(len(es), dtype=bool)
            for k in range(len(es)):
                ends = [int(es.i[k])] + ([int(es.j[k])] if es.kind == "se2" else [])
                if len(ends) == 2 and ends[0] == ends[1]:
                    raise InputError(f"{edge_name(es, k)}: edge from a pose to itself")
                for end in ends:
                    if end in usable:
                        continue
                    if end not in self._seen:
                        raise InputError(
                            f"{edge_name(es, k)}: pose {end} is not in the graph (add it in "
                            "this step or an earlier one)"
                        )
                    keep[k] = False
            has_lines = es.lines.shape[0] == len(es)
            for k in np.flatnonzero(~keep).tolist():
                dropped.append(int(es.lines[k]) if has_lines else 0)
            if keep.any():
                sel = np.flatnonzero(keep)
                lines = es.lines[sel] if has_lines else np.zeros(sel.shape[0])
                part = EdgeSet(
                    es.kind, es.i[sel], es.j[sel], es.measurement[sel], es.information[sel],
                    lines.astype(np.int64),
                )  # fmt: skip
                kept.append((part, U[sel]))
        return kept, dropped

    def _current(self, other: int) -> FloatArray:
        if self._anchor is not None and other == self._anchor[0]:
            return self._anchor[1]
        return self._X[int(np.searchsorted(self._wid, other))]

    def _initial_guess(
        self, pid: int, kept: list[tuple[EdgeSet, FloatArray]], guess: FloatArray | None
    ) -> FloatArray:
        """The given guess, else a prior's measurement, else ``X_i ⊕ Z`` (or ``X_j ⊕ Z⁻¹``)
        from the first edge to a known pose; the first pose may stand alone (the origin)."""
        if guess is not None:
            return guess
        for es, _ in kept:
            if es.kind == "se2_prior":
                at = np.flatnonzero(es.i == pid)
                if at.shape[0]:
                    return es.measurement[int(at[0])].copy()
        for es, _ in kept:
            if es.kind != "se2":
                continue
            for i, j, z in zip(es.i.tolist(), es.j.tolist(), es.measurement, strict=True):
                if j == pid and i != pid:
                    return pose2.compose(self._current(i), z)
                if i == pid and j != pid:
                    return pose2.compose(self._current(j), pose2.inverse(z))
        if self._last_id is None:
            return np.zeros(3)
        raise InputError(
            f"pose {pid}: no edge ties it to a pose in the window (its edges, if any, go to "
            "poses already marginalised out); give it an initial_pose or a longer window"
        )

    # ------------------------------------------------------------------ numerics
    def _system(
        self, X: FloatArray, edge_mask: IntArray | None, ids: IntArray
    ) -> tuple[FloatArray, FloatArray, float]:
        """Dense ``H``, ``g`` over the poses ``ids`` (rows of ``X``) from the window edges
        (``edge_mask``: a subset), and their χ² ``Σ ‖U e‖²``; other ends must be the anchor."""
        n = ids.shape[0]
        ea, eb, ez, eU = self._ea, self._eb, self._ez, self._eU
        if edge_mask is not None:
            ea, eb, ez, eU = ea[edge_mask], eb[edge_mask], ez[edge_mask], eU[edge_mask]
        prior = eb < 0
        Xa = np.vstack([X, np.zeros((1, 3)) if self._anchor is None else self._anchor[1]])
        a = _rows(ids, ea, self._anchor)
        b = np.where(prior, 0, _rows(ids, np.where(prior, ids[0] if n else 0, eb), self._anchor))
        r, J = window_terms(Xa, a, b, ez, eU, prior)
        la = np.where(a < n, a, -1)
        lb = np.where(prior | (b >= n), -1, b)
        l6 = np.repeat(np.stack([la, lb], axis=1), 3, axis=1)
        cols = np.where(l6 >= 0, 3 * l6 + np.tile(np.arange(3), 2), -1)
        flat, vals, g = window_normal_equations(3 * n, cols, r, J)
        H = np.bincount(flat, vals, minlength=9 * n * n + 1)[: 9 * n * n].astype(np.float64)
        H = H.reshape(3 * n, 3 * n)
        return H, g, float(np.einsum("ek,ek->", r, r))

    def _add_prior(self, H: FloatArray, g: FloatArray, ids: IntArray, X_prior: FloatArray) -> float:
        """Add the marginal prior at ``X_prior`` (rows follow its ``pose_ids``) to ``H``, ``g``
        over ``ids`` in place; returns its χ²."""
        p = self._prior
        if p is None:
            return 0.0
        rp, Jp = p.terms(X_prior)
        c = (3 * np.searchsorted(ids, p.pose_ids)[:, None] + np.arange(3)).ravel()
        H[np.ix_(c, c)] += Jp.T @ Jp
        g[c] += Jp.T @ rp
        return float(rp @ rp)

    def _prior_rows(self) -> IntArray:
        assert self._prior is not None
        return np.searchsorted(self._wid, self._prior.pose_ids)

    def _gauss_newton(self, max_iterations: int, tolerance: float) -> tuple[int, float]:
        """Gauss-Newton on the window; returns the iterations and the last ``max |δ|``."""
        n = self._wid.shape[0]
        if n == 0:
            return 0, 0.0
        step = np.inf
        for it in range(1, max_iterations + 1):
            H, g, _ = self._system(self._X, None, self._wid)
            if self._prior is not None:
                self._add_prior(H, g, self._wid, self._X[self._prior_rows()])
            try:
                c = scipy.linalg.cho_factor(H, lower=True, check_finite=False)
            except np.linalg.LinAlgError:
                names = ", ".join(str(q) for q in self._wid[:8].tolist())
                raise GeometryError(
                    f"the window system is singular: poses {names}{' …' if n > 8 else ''} are "
                    "not determined by their edges and the prior"
                ) from None
            delta = -scipy.linalg.cho_solve(c, g, check_finite=False)  # H δ = -g
            if not np.isfinite(delta).all():
                raise ConvergenceError("non-finite Gauss-Newton step", step=self._steps)
            self._X = factors.retract_poses(self._X, delta.reshape(n, 3))
            step = float(np.abs(delta).max())
            if step <= tolerance:
                return it, step
        return max_iterations, step

    def _chi2(self) -> float:
        if self._wid.shape[0] == 0:
            return 0.0
        _, _, chi2 = self._system(self._X, None, self._wid)
        if self._prior is not None:
            rp, _ = self._prior.terms(self._X[self._prior_rows()])
            chi2 += float(rp @ rp)
        return chi2

    def _marginalize_oldest(self) -> int:
        """Schur out the oldest window pose into the prior; returns its id."""
        m = int(self._wid[0])
        touch = (self._ea == m) | (self._eb == m)
        others = np.concatenate([self._ea[touch], self._eb[touch]])
        sep = set(others[np.isin(others, self._wid[1:])].tolist())
        if self._prior is not None:
            sep |= set(self._prior.pose_ids.tolist())
        sep.discard(m)
        ids = np.array([m, *sorted(sep)], dtype=np.int64)
        # Linearised at the current estimate, the old prior too (its residual and Jacobian
        # at X: marginal_prior's module docstring says why not at its first estimates).
        Y_loc = self._X[np.searchsorted(self._wid, ids)]
        H, g, _ = self._system(Y_loc, touch, ids)
        if self._prior is not None:
            self._add_prior(H, g, ids, self._X[self._prior_rows()])
        self._prior = schur_prior(H, g, 3, ids[1:], Y_loc[1:]) if ids.shape[0] > 1 else None
        self._out[self._row[m]] = self._X[0].copy()
        self._left[self._row[m]] = self._steps
        keep = ~touch
        self._ea, self._eb, self._ez, self._eU = (
            self._ea[keep], self._eb[keep], self._ez[keep], self._eU[keep],
        )  # fmt: skip
        self._wid, self._X = self._wid[1:], self._X[1:]
        return m


def _rows(ids: IntArray, q: IntArray, anchor: tuple[int, FloatArray] | None) -> IntArray:
    """Rows of pose ids ``q`` among ``ids`` (increasing); the anchor's row is ``len(ids)``."""
    n = ids.shape[0]
    rows = np.searchsorted(ids, q).clip(max=max(n - 1, 0))
    if anchor is not None:
        rows = np.where(q == anchor[0], n, rows)
    return rows


@runtime.blas_threads()  # the library's thread policy (docs/performance.md)
def smooth_fixed_lag(
    data: GraphData,
    config: FixedLagConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> FixedLagResult:
    """Stream a 2D pose graph through a :class:`FixedLagSmoother`: one step per pose in id
    order with the edges whose later end it is; the first pose starts at the file's vertex
    (the origin without one), the others are chained from their edges.
    ``progress(step, steps)`` runs after every step.

    Raises :class:`~slamkit.errors.InputError` for a graph with landmarks, 3D poses, edge
    kinds other than ``se2`` and ``se2_prior``, fixed poses other than the first, or
    equivalences."""
    kinds = sorted({es.kind for es in data.edges} - set(UPDATE_KINDS))
    if data.dim != 2 or kinds or data.landmark_ids.shape[0]:
        what = f"dim {data.dim}" if data.dim != 2 else f"edge kinds {', '.join(kinds)}"
        if data.dim == 2 and not kinds:
            what = f"{data.landmark_ids.shape[0]} landmarks"
        raise InputError(
            f"{data.source or 'the graph'}: the fixed-lag smoother handles 2D pose graphs "
            f"(se2 and se2_prior edges), got {what}"
        )
    updates = time_ordered_updates(data)
    first = int(updates[0].pose_ids[0]) if updates else None
    if data.equivalences.shape[0] or (
        data.fixed_ids.shape[0] and set(data.fixed_ids.tolist()) != {first}
    ):
        raise InputError(
            f"{data.source or 'the graph'}: the fixed-lag smoother holds only the first pose "
            "fixed; the graph fixes other poses or has equivalences"
        )
    smoother = FixedLagSmoother(config)
    for k, u in enumerate(updates, start=1):
        guess = None if u.initial_poses is None else u.initial_poses[0]
        smoother.update(int(u.pose_ids[0]), u.edges, guess)
        if progress is not None:
            progress(k, len(updates))
    return smoother.finish()
