"""The fixed-lag smoother for 2D pose-landmark graphs: the last ``window`` poses and the
landmarks they observe are the unknowns; older poses and landmarks no window pose observes
any more are marginalised into one prior, and every step costs the same however long the run.

The window after pose 9 with ``window = 3`` (``━`` odometry, ``┄`` observations)::

    marginalised          the prior           the window: X7 X8 X9 and l2, l3
    X0 ━ … ━ X5 ━ X6 ━━[ on X7, l2 ]━━ X7 ━━━━━━ X8 ━━━━━━ X9
             ┆     ┆                   ┆ ┄ l2 ┄┄┄┘          ┆
             l1 ┄┄┄┘ (l1 left with X6)  └┄┄┄┄┄┄┄ l3 ┄┄┄┄┄┄┄┄┘

**The landmark policy.** A landmark enters the window with its first observation (its guess:
that observation from the observing pose's current estimate) and stays an unknown while any
window pose observes it. When the oldest pose ``X_m`` leaves, every landmark that no
*remaining* window pose observes leaves with it: ``X_m`` and those landmarks are eliminated
together (the Schur complement of :mod:`slamkit.optim.marginal_prior`, here over poses and
points: :func:`~slamkit.optim.marginal_prior.schur_square_root`) from every factor touching
them and the old prior, linearised at the current estimate. The separator, on which the new
prior lies, is the next pose and the landmarks that ``X_m`` (or the old prior) shares with the
remaining window. Each landmark's online estimate is its value when it leaves.

*Why this policy and what bounds a step.* Keeping a landmark after its last window observer
has gone would keep unknowns that no window factor touches except the prior: the system
would grow with every landmark ever seen and the step would no longer cost the same. Dropping
it earlier (with its first observer) would turn the later observations into factors of a
marginalised variable. With this policy the unknowns are ``3 L + 2 K`` with ``K`` the
landmarks seen from the ``L`` window poses, at most ``L`` times the most landmarks one pose
observes; the prior is on at most the next pose and those ``K`` landmarks. A step solves a
dense system of that size (``O((3L + 2K)³)``), whatever the step number.

**A landmark seen again after it left** (the robot back at a place it mapped before) cannot
be tied to its old variable without the joint Gaussian that marginalisation discarded (the
pose smoother's reason for dropping loop closures, :mod:`slamkit.optim.fixed_lag`). Here the
observation *re-enters* the landmark as a fresh variable, with no link to the old one: the
window still uses it as a local map point (it constrains the window's poses among
themselves), and the information behind the old estimate is not used twice. Re-entries are
counted; an odometry edge to a marginalised pose is dropped and counted.

**Gauge and batch.** The first pose is the anchor, held fixed at its guess (the origin, or
its vertex). With a window that holds the whole run nothing is marginalised and
:meth:`LandmarkFixedLagSmoother.finish` converges Gauss-Newton on the whole graph: the batch
optimum (tested).

Factors: ``se2`` (odometry and loop edges between poses), ``se2_xy`` (iSAM's landmark in the
robot frame) and ``range_bearing`` (the landmark graph's readings) — residuals and
Jacobians from :mod:`slamkit.optim.factors`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from slamkit import runtime
from slamkit.errors import ConvergenceError, CovarianceError, GeometryError, InputError
from slamkit.geometry import pose2
from slamkit.optim import factors
from slamkit.optim.data import EdgeSet, FloatArray, GraphData, IntArray
from slamkit.optim.fixed_lag import FINISH_MAX_ITERATIONS, FINISH_STEP_TOLERANCE, FixedLagConfig
from slamkit.optim.marginal_prior import schur_square_root
from slamkit.optim.updates import edge_name
from slamkit.optim.window import window_normal_equations

__all__ = [
    "LANDMARK_KINDS",
    "LandmarkFixedLagResult",
    "LandmarkFixedLagSmoother",
    "LandmarkStepInfo",
    "PoseLandmarkPrior",
    "landmark_updates",
    "smooth_landmark_fixed_lag",
]

LANDMARK_KINDS = ("se2_xy", "range_bearing")
"""Observation kinds the smoother takes (each a 2D measurement of a point from a pose)."""


@dataclass(frozen=True)
class PoseLandmarkPrior:
    """A linear factor ``‖R e + d‖²`` on poses and points, ``e`` the stacked local
    coordinates around the linearisation point: per pose the chart of
    :class:`~slamkit.optim.marginal_prior.MarginalPrior` (``X̄⁻¹ X``, 3 entries), then per
    point ``p - p̄`` (2 entries)."""

    pose_ids: IntArray  # (k,)
    point_keys: IntArray  # (q,) the smoother's landmark variables
    point_ids: IntArray  # (q,) their landmark ids in the graph
    pose_point: FloatArray  # (k, 3) X̄
    point_point: FloatArray  # (q, 2) p̄
    R: FloatArray  # (r, 3k + 2q)
    d: FloatArray  # (r,)

    def terms(self, X: FloatArray, P: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Whitened residual ``(r,)`` and its first-estimate Jacobian ``R`` at poses ``X``
        ``(k, 3)`` and points ``P`` ``(q, 2)`` (rows as the ids)."""
        e_pose, _ = factors.se2_prior_error(X, self.pose_point)
        e = np.concatenate([e_pose.ravel(), (P - self.point_point).ravel()])
        return self.R @ e + self.d, self.R


@dataclass(frozen=True)
class LandmarkStepInfo:
    """What one :meth:`LandmarkFixedLagSmoother.update` did."""

    step: int
    pose_id: int
    unknowns: int  # 3 · window poses + 2 · landmarks after the step
    landmarks: int  # landmark variables in the window after the step
    iterations: int
    dropped: int  # odometry edges to poses already marginalised out
    reentered: int  # observations that re-entered a landmark that had left
    seconds: float


@dataclass(frozen=True)
class LandmarkFixedLagResult:
    """The output of :meth:`LandmarkFixedLagSmoother.finish`; rows follow the ids."""

    pose_ids: IntArray  # arrival order
    poses: FloatArray  # online estimate as each left; the final window's at the end
    initial_poses: FloatArray
    landmark_ids: IntArray  # sorted file ids
    landmarks: FloatArray  # the latest variable of each: online estimate or final window
    initial_landmarks: FloatArray  # the guess from each landmark's first observation
    converged: bool
    window: int
    steps: int
    step_seconds: FloatArray
    step_iterations: IntArray
    max_unknowns: int
    max_prior_size: int  # unknowns the prior spans at most
    dropped_edges: int
    reentries: int
    finish_seconds: float


@dataclass
class _Obs:
    """The window's observations (kind 0 se2_xy, 1 range_bearing)."""

    kind: IntArray
    pose: IntArray
    key: IntArray
    z: FloatArray
    U: FloatArray


def _whiten(es: EdgeSet, dim: int) -> FloatArray:
    """``U`` with ``UᵀU = Ω`` per edge; shapes, NaN and definiteness checked, naming the edge."""
    n = len(es)
    if es.measurement.shape != (n, dim) or es.information.shape != (n, dim, dim):
        raise InputError(
            f"{es.kind} edges: measurement {es.measurement.shape} and information "
            f"{es.information.shape}, expected ({n}, {dim}) and ({n}, {dim}, {dim})"
        )
    bad = ~(np.isfinite(es.measurement).all(axis=1) & np.isfinite(es.information).all(axis=(1, 2)))
    if bad.any():
        raise InputError(f"{edge_name(es, int(np.flatnonzero(bad)[0]))}: NaN or infinity")
    try:
        L = np.linalg.cholesky(es.information)
    except np.linalg.LinAlgError:
        k = int(np.argmin(np.linalg.eigvalsh(es.information).min(axis=1)))
        raise CovarianceError(
            f"{edge_name(es, k)}: information matrix not positive definite"
        ) from None
    return np.swapaxes(L, 1, 2)


def _point_from(kind: int, x: FloatArray, z: FloatArray) -> FloatArray:
    """The point an observation ``z`` from pose ``x`` places."""
    if kind == 0:
        return pose2.transform_points(x, z[None, :])[0]
    a = x[2] + z[1]
    return np.array([x[0] + z[0] * np.cos(a), x[1] + z[0] * np.sin(a)])


class LandmarkFixedLagSmoother:
    """A 2D pose-landmark graph smoothed over a window of poses (module docstring).

    ``update(pose_id, edges)`` adds a pose with its odometry (``se2`` edges whose later end
    it is) and its observations (``se2_xy`` or ``range_bearing`` edges from it);
    ``finish()`` converges the last window and returns the result.
    """

    def __init__(self, config: FixedLagConfig | None = None) -> None:
        self.config = config if config is not None else FixedLagConfig()
        self._wid = np.zeros(0, dtype=np.int64)
        self._X = np.zeros((0, 3))
        self._anchor: tuple[int, FloatArray] | None = None
        self._lkey = np.zeros(0, dtype=np.int64)  # window landmark variables, increasing
        self._P = np.zeros((0, 2))
        self._key_of: dict[int, int] = {}  # file landmark id → its current variable
        self._file_of: dict[int, int] = {}  # variable → file landmark id
        self._next_key = 0
        self._oa = np.zeros(0, dtype=np.int64)  # odometry: pose ids
        self._ob = np.zeros(0, dtype=np.int64)
        self._oz = np.zeros((0, 3))
        self._oU = np.zeros((0, 3, 3))
        self._obs = _Obs(
            np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64),
            np.zeros((0, 2)), np.zeros((0, 2, 2)),
        )  # fmt: skip
        self._prior: PoseLandmarkPrior | None = None
        self._step_dropped = 0
        self._ids: list[int] = []
        self._row: dict[int, int] = {}
        self._out: list[FloatArray] = []
        self._guess: list[FloatArray] = []
        self._lm_out: dict[int, FloatArray] = {}
        self._lm_first: dict[int, FloatArray] = {}
        self._seconds: list[float] = []
        self._iterations: list[int] = []
        self._max_unknowns = 0
        self._max_prior = 0
        self._dropped = 0
        self._reentries = 0

    # ------------------------------------------------------------------ accessors
    def window_estimate(self) -> tuple[IntArray, FloatArray, IntArray, FloatArray]:
        """``(pose_ids, poses, landmark file ids, landmarks)`` of the window (copies)."""
        ids = np.array([self._file_of[int(k)] for k in self._lkey], dtype=np.int64)
        return self._wid.copy(), self._X.copy(), ids, self._P.copy()

    def prior(self) -> PoseLandmarkPrior | None:
        """The marginal prior on the window (``None`` before the first marginalisation)."""
        return self._prior

    # ------------------------------------------------------------------ a step
    def update(
        self,
        pose_id: int,
        edges: Sequence[EdgeSet] = (),
        initial_pose: FloatArray | None = None,
    ) -> LandmarkStepInfo:
        """Add pose ``pose_id`` (above every id so far) with its edges and run one step; its
        guess is ``initial_pose`` when given, else its first odometry edge (the first pose:
        the origin)."""
        t0 = time.perf_counter()
        pid = int(pose_id)
        if self._ids and pid <= self._ids[-1]:
            raise InputError(f"pose {pid} arrives after pose {self._ids[-1]}: ids must increase")
        odo, obs = self._split(pid, edges)
        if initial_pose is not None:
            x_new = np.asarray(initial_pose, dtype=np.float64).reshape(3).copy()
            if not np.isfinite(x_new).all():
                raise InputError(f"pose {pid}: NaN or infinity in its initial pose")
        else:
            x_new = self._pose_guess(pid, odo)
        self._row[pid] = len(self._ids)
        self._ids.append(pid)
        self._guess.append(x_new)
        self._out.append(x_new)
        if self._anchor is None:
            self._anchor = (pid, x_new)
        else:
            self._wid = np.append(self._wid, pid)
            self._X = np.vstack([self._X, x_new[None, :]])
        for es, U in odo:
            self._oa = np.concatenate([self._oa, es.i])
            self._ob = np.concatenate([self._ob, es.j])
            self._oz = np.concatenate([self._oz, es.measurement])
            self._oU = np.concatenate([self._oU, U])
        reentered = self._add_observations(pid, x_new, obs)
        iterations, _ = self._gauss_newton(self.config.max_iterations, self.config.step_tolerance)
        if self._wid.shape[0] > self.config.window:
            self._marginalize_oldest()
        seconds = time.perf_counter() - t0
        self._seconds.append(seconds)
        self._iterations.append(iterations)
        unknowns = 3 * self._wid.shape[0] + 2 * self._lkey.shape[0]
        self._max_unknowns = max(self._max_unknowns, unknowns)
        if self._prior is not None:
            self._max_prior = max(self._max_prior, int(self._prior.R.shape[1]))
        return LandmarkStepInfo(
            len(self._ids), pid, unknowns, int(self._lkey.shape[0]), iterations,
            self._step_dropped, reentered, seconds,
        )  # fmt: skip

    def finish(self) -> LandmarkFixedLagResult:
        """Converge the last window (to ``FINISH_STEP_TOLERANCE``) and return the result."""
        if not self._ids:
            raise InputError("the smoother has no poses: call update() first")
        t0 = time.perf_counter()
        _, step = self._gauss_newton(FINISH_MAX_ITERATIONS, FINISH_STEP_TOLERANCE)
        for pid, x in zip(self._wid.tolist(), self._X, strict=True):
            self._out[self._row[pid]] = x.copy()
        for k, p in zip(self._lkey.tolist(), self._P, strict=True):
            self._lm_out[self._file_of[k]] = p.copy()
        lm_ids = np.array(sorted(self._lm_out), dtype=np.int64)
        return LandmarkFixedLagResult(
            pose_ids=np.array(self._ids, dtype=np.int64),
            poses=np.array(self._out).reshape(-1, 3),
            initial_poses=np.array(self._guess).reshape(-1, 3),
            landmark_ids=lm_ids,
            landmarks=np.array([self._lm_out[int(i)] for i in lm_ids]).reshape(-1, 2),
            initial_landmarks=np.array([self._lm_first[int(i)] for i in lm_ids]).reshape(-1, 2),
            converged=step <= FINISH_STEP_TOLERANCE,
            window=self.config.window,
            steps=len(self._ids),
            step_seconds=np.array(self._seconds),
            step_iterations=np.array(self._iterations, dtype=np.int64),
            max_unknowns=self._max_unknowns,
            max_prior_size=self._max_prior,
            dropped_edges=self._dropped,
            reentries=self._reentries,
            finish_seconds=time.perf_counter() - t0,
        )

    # ------------------------------------------------------------------ input
    def _split(
        self, pid: int, edges: Sequence[EdgeSet]
    ) -> tuple[list[tuple[EdgeSet, FloatArray]], list[tuple[int, EdgeSet, FloatArray]]]:
        """Odometry kept (edges to marginalised poses dropped and counted) and observations."""
        held = set(self._wid.tolist()) | {pid}
        if self._anchor is not None:
            held.add(self._anchor[0])
        odo: list[tuple[EdgeSet, FloatArray]] = []
        obs: list[tuple[int, EdgeSet, FloatArray]] = []
        self._step_dropped = 0
        for es in edges:
            if es.kind == "se2":
                U = _whiten(es, 3)
                later = np.maximum(es.i, es.j)
                if (later != pid).any() or (es.i == es.j).any():
                    k = int(np.flatnonzero((later != pid) | (es.i == es.j))[0])
                    raise InputError(f"{edge_name(es, k)}: not an edge to pose {pid} from before")
                keep = np.array(
                    [int(a) in held and int(b) in held for a, b in zip(es.i, es.j, strict=True)]
                )
                self._step_dropped += int((~keep).sum())
                sub = EdgeSet("se2", es.i[keep], es.j[keep], es.measurement[keep],
                              es.information[keep], es.lines[keep])  # fmt: skip
                odo.append((sub, U[keep]))
            elif es.kind in LANDMARK_KINDS:
                if (es.i != pid).any():
                    k = int(np.flatnonzero(es.i != pid)[0])
                    raise InputError(
                        f"{edge_name(es, k)}: an observation of step {pid} from another pose"
                    )
                obs.append((LANDMARK_KINDS.index(es.kind), es, _whiten(es, 2)))
            else:
                raise InputError(
                    f"edge kind {es.kind!r}: the landmark fixed-lag smoother takes se2, "
                    f"{' and '.join(LANDMARK_KINDS)}"
                )
        self._dropped += self._step_dropped
        return odo, obs

    def _current(self, q: int) -> FloatArray:
        if self._anchor is not None and q == self._anchor[0]:
            return self._anchor[1]
        return self._X[int(np.searchsorted(self._wid, q))]

    def _pose_guess(self, pid: int, odo: list[tuple[EdgeSet, FloatArray]]) -> FloatArray:
        for es, _ in odo:
            for i, j, z in zip(es.i.tolist(), es.j.tolist(), es.measurement, strict=True):
                if j == pid:
                    return pose2.compose(self._current(i), z)
                return pose2.compose(self._current(j), pose2.inverse(z))
        if not self._ids:
            return np.zeros(3)
        raise InputError(f"pose {pid}: no odometry edge ties it to a pose in the window")

    def _add_observations(
        self, pid: int, x: FloatArray, obs: list[tuple[int, EdgeSet, FloatArray]]
    ) -> int:
        """Append the observations; new (or re-entering) landmarks get a variable and a guess."""
        reentered = 0
        o = self._obs
        for kind, es, U in obs:
            keys = np.empty(len(es), dtype=np.int64)
            for k, (lid, z) in enumerate(zip(es.j.tolist(), es.measurement, strict=True)):
                key = self._key_of.get(lid)
                if key is None:
                    if lid in self._lm_out:
                        reentered += 1
                    key = self._next_key
                    self._next_key += 1
                    self._key_of[lid] = key
                    self._file_of[key] = lid
                    self._lkey = np.append(self._lkey, key)
                    p = _point_from(kind, x, z)
                    self._lm_first.setdefault(lid, p)
                    self._P = np.vstack([self._P, p[None, :]])
                keys[k] = key
            o.kind = np.concatenate([o.kind, np.full(len(es), kind, dtype=np.int64)])
            o.pose = np.concatenate([o.pose, es.i])
            o.key = np.concatenate([o.key, keys])
            o.z = np.concatenate([o.z, es.measurement])
            o.U = np.concatenate([o.U, U])
        self._reentries += reentered
        return reentered

    # ------------------------------------------------------------------ numerics
    def _system(
        self,
        pose_ids: IntArray,
        X: FloatArray,
        keys: IntArray,
        P: FloatArray,
        odo_mask: np.ndarray | None,
        obs_mask: np.ndarray | None,
    ) -> tuple[FloatArray, FloatArray]:
        """Dense ``H``, ``g`` over ``pose_ids`` (3 columns each) then ``keys`` (2 each) from
        the window's factors (masks: a subset); other pose ends must be the anchor."""
        n, m = pose_ids.shape[0], keys.shape[0]
        size = 3 * n + 2 * m
        H = np.zeros(size * size)
        g = np.zeros(size)
        Xa = np.vstack([X, np.zeros((1, 3)) if self._anchor is None else self._anchor[1]])
        om = slice(None) if odo_mask is None else odo_mask
        if self._oa[om].shape[0]:
            a = self._pose_rows(pose_ids, self._oa[om])
            b = self._pose_rows(pose_ids, self._ob[om])
            e, Ja, Jb = factors.se2_between_error(Xa[a], Xa[b], self._oz[om])
            U = self._oU[om]
            r = np.einsum("eij,ej->ei", U, e)
            J = U @ np.concatenate([Ja, Jb], axis=2)
            cols = np.concatenate([self._pose_cols(a, n), self._pose_cols(b, n)], axis=1)
            flat, vals, gg = window_normal_equations(size, cols, r, J)
            H += np.bincount(flat, vals, minlength=size * size + 1)[: size * size]
            g += gg
        o = self._obs
        bm = np.ones(o.kind.shape[0], dtype=bool) if obs_mask is None else obs_mask
        for kind, fn in enumerate((factors.se2_xy_error, factors.range_bearing_error)):
            sel = bm & (o.kind == kind)
            if not sel.any():
                continue
            a = self._pose_rows(pose_ids, o.pose[sel])
            c = np.searchsorted(keys, o.key[sel])
            e, Ji, Jl = fn(Xa[a], P[c], o.z[sel])
            r = np.einsum("eij,ej->ei", o.U[sel], e)
            J = o.U[sel] @ np.concatenate([Ji, Jl], axis=2)
            lcols = 3 * n + 2 * c[:, None] + np.arange(2)
            cols = np.concatenate([self._pose_cols(a, n), lcols], axis=1)
            flat, vals, gg = window_normal_equations(size, cols, r, J)
            H += np.bincount(flat, vals, minlength=size * size + 1)[: size * size]
            g += gg
        return H.reshape(size, size), g

    def _pose_rows(self, pose_ids: IntArray, q: IntArray) -> IntArray:
        """Rows of pose ids ``q`` among ``pose_ids``; the anchor's row is ``len(pose_ids)``."""
        n = pose_ids.shape[0]
        rows = np.searchsorted(pose_ids, q).clip(max=max(n - 1, 0))
        if self._anchor is not None:
            rows = np.where(q == self._anchor[0], n, rows)
        return rows

    @staticmethod
    def _pose_cols(rows: IntArray, n: int) -> IntArray:
        return np.where(rows[:, None] < n, 3 * rows[:, None] + np.arange(3), -1)

    def _prior_cols(self, pose_ids: IntArray, keys: IntArray) -> IntArray:
        """Columns of the prior's unknowns in a system over ``pose_ids`` then ``keys``."""
        assert self._prior is not None
        p = self._prior
        pc = 3 * np.searchsorted(pose_ids, p.pose_ids)[:, None] + np.arange(3)
        lc = 3 * pose_ids.shape[0] + 2 * np.searchsorted(keys, p.point_keys)[:, None] + np.arange(2)
        return np.concatenate([pc.ravel(), lc.ravel()])

    def _add_prior(self, H: FloatArray, g: FloatArray, pose_ids: IntArray, keys: IntArray) -> None:
        """The prior at the window's current estimate, added in place over the given order."""
        p = self._prior
        if p is None:
            return
        Xp = self._X[np.searchsorted(self._wid, p.pose_ids)]
        Pp = self._P[np.searchsorted(self._lkey, p.point_keys)]
        rp, Jp = p.terms(Xp, Pp)
        c = self._prior_cols(pose_ids, keys)
        H[np.ix_(c, c)] += Jp.T @ Jp
        g[c] += Jp.T @ rp

    def _gauss_newton(self, max_iterations: int, tolerance: float) -> tuple[int, float]:
        n, m = self._wid.shape[0], self._lkey.shape[0]
        if n + m == 0:
            return 0, 0.0
        step = np.inf
        for it in range(1, max_iterations + 1):
            H, g = self._system(self._wid, self._X, self._lkey, self._P, None, None)
            self._add_prior(H, g, self._wid, self._lkey)
            try:
                c = scipy.linalg.cho_factor(H, lower=True, check_finite=False)
            except np.linalg.LinAlgError:
                raise GeometryError(
                    f"the window system is singular at pose {self._ids[-1]}: a pose or landmark "
                    "is not determined by its factors and the prior"
                ) from None
            delta = -scipy.linalg.cho_solve(c, g, check_finite=False)  # H δ = -g
            if not np.isfinite(delta).all():
                raise ConvergenceError("non-finite Gauss-Newton step", step=len(self._ids))
            self._X = factors.retract_poses(self._X, delta[: 3 * n].reshape(n, 3))
            self._P = self._P + delta[3 * n :].reshape(m, 2)
            step = float(np.abs(delta).max())
            if step <= tolerance:
                return it, step
        return max_iterations, step

    def _marginalize_oldest(self) -> None:
        """Eliminate the oldest pose and the landmarks only it still observes (module
        docstring) into the new prior."""
        mid = int(self._wid[0])
        o = self._obs
        stay_obs = np.isin(o.pose, self._wid[1:])
        seen = np.unique(o.key[stay_obs])
        gone = self._lkey[~np.isin(self._lkey, seen)]  # landmarks leaving with the pose
        odo_touch = (self._oa == mid) | (self._ob == mid)
        obs_touch = (o.pose == mid) | np.isin(o.key, gone)
        sep_p = set(self._oa[odo_touch].tolist()) | set(self._ob[odo_touch].tolist())
        sep_l = set(o.key[obs_touch].tolist())
        if self._prior is not None:
            sep_p |= set(self._prior.pose_ids.tolist())
            sep_l |= set(self._prior.point_keys.tolist())
        sep_p = {q for q in sep_p if q in set(self._wid[1:].tolist())}
        sep_l -= set(gone.tolist())
        s_p = np.array(sorted(sep_p), dtype=np.int64)
        s_l = np.array(sorted(sep_l), dtype=np.int64)
        pose_ids = np.concatenate([[mid], s_p]).astype(np.int64)
        keys = np.concatenate([gone, s_l]).astype(np.int64)
        order = np.argsort(keys, kind="stable")  # _system wants increasing keys
        keys_sorted = keys[order]
        X = self._X[np.searchsorted(self._wid, pose_ids)]
        P = self._P[np.searchsorted(self._lkey, keys_sorted)]
        H, g = self._system(pose_ids, X, keys_sorted, P, odo_touch, obs_touch)
        self._add_prior(H, g, pose_ids, keys_sorted)
        # columns in elimination order: [X_m, gone landmarks, separator poses, separator points]
        n = pose_ids.shape[0]
        lcol = 3 * n + 2 * np.argsort(order)[:, None] + np.arange(2)  # column of keys[k]
        perm = np.concatenate([np.arange(3), lcol[: gone.shape[0]].ravel(),
                               np.arange(3, 3 * n), lcol[gone.shape[0]:].ravel()])  # fmt: skip
        H, g = H[np.ix_(perm, perm)], g[perm]
        if s_p.shape[0] + s_l.shape[0]:
            R, d = schur_square_root(H, g, 3 + 2 * gone.shape[0])
            file_ids = np.array([self._file_of[int(k)] for k in s_l], dtype=np.int64)
            self._prior = PoseLandmarkPrior(
                s_p, s_l, file_ids, X[1:], P[np.searchsorted(keys_sorted, s_l)], R, d
            )
        else:
            self._prior = None
        self._out[self._row[mid]] = self._X[0].copy()
        out_rows = np.searchsorted(self._lkey, gone)
        for k, row in zip(gone.tolist(), out_rows.tolist(), strict=True):
            self._lm_out[self._file_of[k]] = self._P[row].copy()
            del self._key_of[self._file_of[k]]
        keep_l = ~np.isin(self._lkey, gone)
        self._lkey, self._P = self._lkey[keep_l], self._P[keep_l]
        self._oa, self._ob = self._oa[~odo_touch], self._ob[~odo_touch]
        self._oz, self._oU = self._oz[~odo_touch], self._oU[~odo_touch]
        keep_o = ~obs_touch
        self._obs = _Obs(o.kind[keep_o], o.pose[keep_o], o.key[keep_o], o.z[keep_o], o.U[keep_o])
        self._wid, self._X = self._wid[1:], self._X[1:]


def landmark_updates(data: GraphData) -> list[tuple[int, tuple[EdgeSet, ...]]]:
    """One step per pose in increasing id order: ``(pose_id, edges)`` with the ``se2`` edges
    whose later end it is and the observations made from it."""
    bad = sorted({e.kind for e in data.edges} - {"se2", *LANDMARK_KINDS})
    if data.dim != 2 or bad:
        what = f"dim {data.dim}" if data.dim != 2 else f"edge kinds {', '.join(bad)}"
        raise InputError(
            f"{data.source or 'the graph'}: the landmark fixed-lag smoother takes 2D graphs of "
            f"se2, se2_xy and range_bearing edges, got {what}"
        )
    refs = [e.i for e in data.edges] + [e.j for e in data.edges if e.kind == "se2"]
    ids = np.unique(np.concatenate([data.pose_ids, *refs]).astype(np.int64))
    if data.fixed_ids.shape[0] and set(data.fixed_ids.tolist()) != {int(ids[0])}:
        raise InputError(
            f"{data.source or 'the graph'}: the smoother holds only the first pose fixed"
        )
    per: dict[int, list[EdgeSet]] = {int(q): [] for q in ids}
    for es in data.edges:
        owner = np.maximum(es.i, es.j) if es.kind == "se2" else es.i
        order = np.argsort(owner, kind="stable")
        owner_sorted = owner[order]
        starts = np.flatnonzero(np.r_[True, owner_sorted[1:] != owner_sorted[:-1]])
        for s, t in zip(starts, np.r_[starts[1:], owner_sorted.shape[0]], strict=True):
            rows = order[s:t]
            per[int(owner_sorted[s])].append(
                EdgeSet(es.kind, es.i[rows], es.j[rows], es.measurement[rows],
                        es.information[rows], es.lines[rows] if es.lines.shape[0] else
                        np.zeros(rows.shape[0], dtype=np.int64))
            )  # fmt: skip
    return [(q, tuple(per[q])) for q in sorted(per)]


@runtime.blas_threads()  # the library's thread policy (docs/performance.md)
def smooth_landmark_fixed_lag(
    data: GraphData,
    config: FixedLagConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    first_pose: FloatArray | None = None,
) -> LandmarkFixedLagResult:
    """Stream a 2D pose-landmark graph through a :class:`LandmarkFixedLagSmoother`
    (:func:`landmark_updates`); the anchor is ``first_pose``, else the graph's first vertex,
    else the origin. ``progress(step, steps)`` runs after every step."""
    steps = landmark_updates(data)
    smoother = LandmarkFixedLagSmoother(config)
    anchor = first_pose
    if anchor is None and data.poses.shape[0]:
        anchor = data.poses[int(np.argmin(data.pose_ids))]
    for k, (pid, edges) in enumerate(steps, start=1):
        smoother.update(pid, edges, anchor if k == 1 else None)
        if progress is not None:
            progress(k, len(steps))
    return smoother.finish()
