"""FastSLAM 1.0 and 2.0: the vectorised kernels against a per-particle reference, resampling
without aliasing, weight underflow, convergence on simulated worlds, reproducibility."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from slamkit.datasets import load_dataset
from slamkit.datasets.stream import (
    Control,
    Dataset,
    LandmarkReadings,
    LandmarkSensorSpec,
    MotionSpec,
    Odometry,
)
from slamkit.errors import (
    ConfigError,
    ConvergenceError,
    CovarianceError,
    GeometryError,
    InputError,
    NonFiniteError,
)
from slamkit.estimation.particles import (
    effective_sample_size,
    low_variance_resample,
    low_variance_resample_unchecked,
    particle_estimate,
)
from slamkit.eval import absolute_trajectory_error, landmark_map_error
from slamkit.geometry.alignment import align_points_2d
from slamkit.models import (
    Ackermann,
    DifferentialDrive,
    OdometryModel,
    RangeBearing,
    RangeOnly,
    RelativePosition,
    UnicycleArc,
    UnicycleEuler,
    odometry_control,
    propagate_gaussian,
)
from slamkit.pipeline.registry import EstimatorEntry
from slamkit.pipeline.runner import run
from slamkit.sim import observe_landmarks
from slamkit.slam.fastslam import (
    FastSlam1,
    FastSlam2,
    FastSlamConfig,
    FastSlamParticles,
    UpdateSettings,
    default_p0,
    fastslam1_update,
    fastslam2_update,
    fastslam_predict,
    fastslam_resample,
)

ENTRIES = {
    v: EstimatorEntry(
        f"fastslam{v}",
        f"FastSLAM {v}.0",
        f"slamkit.slam.fastslam:FastSlam{v}",
        "slamkit.slam.fastslam:FastSlamConfig",
        requires=("motion", "landmark_sensor"),
    )
    for v in (1, 2)
}

R = np.diag([0.1**2, np.deg2rad(2.0) ** 2])
Q_U = np.diag([0.3**2, np.deg2rad(15.0) ** 2])
FIRST_UNLABELLED = 100


# --------------------------------------------------------------------------------------------
# A straightforward per-particle reference (plain loops, 2×2 numpy per landmark)
# --------------------------------------------------------------------------------------------


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _h_and_jac(x, m):
    """Range-bearing h, H_x and H_m written out by hand (not the library's model)."""
    dx, dy = m[0] - x[0], m[1] - x[1]
    q = dx * dx + dy * dy
    r = math.sqrt(q)
    zh = np.array([r, _wrap(math.atan2(dy, dx) - x[2])])
    Hm = np.array([[dx / r, dy / r], [-dy / q, dx / q]])
    Hx = np.array([[-dx / r, -dy / r, 0.0], [dy / q, -dx / q, -1.0]])
    return zh, Hx, Hm


def _inverse(x, z):
    a = x[2] + z[1]
    m = np.array([x[0] + z[0] * math.cos(a), x[1] + z[0] * math.sin(a)])
    Lz = np.array([[math.cos(a), -z[0] * math.sin(a)], [math.sin(a), z[0] * math.cos(a)]])
    return m, Lz


def innovation_unchecked(x, lm, z):
    zh, Hx, Hm = _h_and_jac(x, lm["mu"])
    nu = z - zh
    nu[1] = _wrap(nu[1])
    Q = Hm @ lm["cov"] @ Hm.T + R
    return nu, Hx, Hm, Q


def _loglik(nu, S):
    return float(
        -0.5 * (nu @ np.linalg.inv(S) @ nu) - 0.5 * math.log(np.linalg.det(2 * math.pi * S))
    )


def _ref_ekf(x, lm, z):
    nu, _, H, Q = innovation_unchecked(x, lm, z)
    K = lm["cov"] @ H.T @ np.linalg.inv(Q)
    A = np.eye(2) - K @ H
    P = A @ lm["cov"] @ A.T + K @ R @ K.T
    lm["mu"] = lm["mu"] + K @ nu
    lm["cov"] = 0.5 * (P + P.T)


def _ref_new(x, z, lid):
    m, Lz = _inverse(x, z)
    C = Lz @ R @ Lz.T
    return {"id": lid, "mu": m, "cov": 0.5 * (C + C.T), "counter": 1}


def _to_lists(ps: FastSlamParticles):
    out = []
    for p in range(len(ps)):
        lms = [
            {
                "id": int(ps.ids[p, j]),
                "mu": ps.means[p, j].copy(),
                "cov": ps.covs[p, j].copy(),
                "counter": int(ps.counters[p, j]),
            }
            for j in range(int(ps.counts[p]))
        ]
        out.append({"pose": ps.poses[p].copy(), "logw": float(ps.log_weights[p]), "lms": lms})
    return out


def _ref_associate(x, lms, z, rid, s, seen, marginal=None):
    """Slot (or -1 = new) and log-likelihood of one reading in one particle."""
    if s.use_ids and rid >= 0:
        for j, lm in enumerate(lms):
            if lm["id"] == rid:
                nu, Hx, _, Q = innovation_unchecked(x, lm, z)
                L = Q if marginal is None else marginal(Hx, Q)
                return j, _loglik(nu, L)
        return -1, math.log(s.p0)
    best, best_ll = -1, -math.inf
    for j, lm in enumerate(lms):
        if j in seen:
            continue
        nu, Hx, _, Q = innovation_unchecked(x, lm, z)
        ll = _loglik(nu, Q if marginal is None else marginal(Hx, Q))
        if ll > best_ll:
            best, best_ll = j, ll
    if best < 0 or best_ll < math.log(s.p0):
        return -1, math.log(s.p0)
    return best, best_ll


def _ref_prune(x, lms, seen, updated, s):
    """Counters of the landmarks that can be removed (started by unlabelled readings);
    those known by an id keep theirs unchanged."""
    if not s.prune:
        return lms
    for j, lm in enumerate(lms):
        if lm["id"] < s.first_unlabelled_id:
            continue
        dx, dy = lm["mu"][0] - x[0], lm["mu"][1] - x[1]
        r = math.hypot(dx, dy)
        b = _wrap(math.atan2(dy, dx) - x[2])
        visible = s.visible_min_range <= r <= s.visible_max_range and abs(b) <= s.fov / 2
        if j in updated:
            lm["counter"] += 1
        elif visible and j not in seen:
            lm["counter"] -= 1
    return [lm for lm in lms if not (lm["counter"] < 0 and lm["id"] >= s.first_unlabelled_id)]


def _ref_normalise(parts):
    lw = np.array([p["logw"] for p in parts])
    m = lw.max()
    total = m + math.log(sum(math.exp(v - m) for v in lw))
    for p in parts:
        p["logw"] -= total


def _order(ids, s):
    """Labelled readings first, then unlabelled ones, each in reading order."""
    lab = [k for k in range(len(ids)) if s.use_ids and ids[k] >= 0]
    return lab + [k for k in range(len(ids)) if k not in lab]


def ref_update1(ps: FastSlamParticles, z, ids, s: UpdateSettings):
    """FastSLAM 1.0 update, particle by particle (readings outer, so ids can be shared)."""
    parts, next_id = _to_lists(ps), ps.next_id
    seen = [set() for _ in parts]
    updated = [set() for _ in parts]
    for k in _order(ids, s):
        zk, rk = z[k], int(ids[k])
        spawned = False
        for i, p in enumerate(parts):
            j, ll = _ref_associate(p["pose"], p["lms"], zk, rk, s, seen[i])
            p["logw"] += ll
            if j >= 0:
                _ref_ekf(p["pose"], p["lms"][j], zk)
                seen[i].add(j)
                updated[i].add(j)
            else:
                lid = rk if (s.use_ids and rk >= 0) else next_id
                spawned |= lid == next_id and not (s.use_ids and rk >= 0)
                p["lms"].append(_ref_new(p["pose"], zk, lid))
                seen[i].add(len(p["lms"]) - 1)
        if spawned:
            next_id += 1
    for i, p in enumerate(parts):
        p["lms"] = _ref_prune(p["pose"], p["lms"], seen[i], updated[i], s)
    _ref_normalise(parts)
    return parts, next_id


def _ref_motion(x, u, dt):
    v, w = u
    g = np.array(
        [x[0] + v * math.cos(x[2]) * dt, x[1] + v * math.sin(x[2]) * dt, _wrap(x[2] + w * dt)]
    )
    V = np.array([[math.cos(x[2]) * dt, 0.0], [math.sin(x[2]) * dt, 0.0], [0.0, dt]])
    return g, V


def _ref_motion_full(x, u, dt, delta, b):
    """The Euler step at noise ``delta`` (``b = 3``: pose error first, then control noise)
    and its Jacobian with respect to ``delta`` (``[G, V]`` or ``V``)."""
    xa = x + delta[:3] if b else x
    g, V = _ref_motion(xa, u + delta[b:], dt)
    if not b:
        return g, V
    v = (u + delta[b:])[0]
    G = np.array([[1.0, 0.0, -v * math.sin(xa[2]) * dt], [0.0, 1.0, v * math.cos(xa[2]) * dt],
                  [0.0, 0.0, 1.0]])  # fmt: skip
    return g, np.hstack([G, V])


def ref_update2(ps: FastSlamParticles, u, dt, z, ids, s: UpdateSettings, draws, pose_cov=None):
    """FastSLAM 2.0 step, particle by particle; ``draws (P, d)`` standard normals; with
    ``pose_cov (P, 3, 3)`` the proposal is over ``(pose error, control noise)``."""
    parts, next_id = _to_lists(ps), ps.next_id
    n = len(parts)
    b = 0 if pose_cov is None else 3
    e = [np.zeros(b + 2) for _ in range(n)]
    Se = [np.zeros((b + 2, b + 2)) for _ in range(n)]
    for i in range(n):
        Se[i][b:, b:] = Q_U
        if b:
            Se[i][:3, :3] = pose_cov[i]
    seen = [set() for _ in range(n)]
    forced: dict[int, list[int] | None] = {}
    used_ids: set[int] = set()
    for k in _order(ids, s):
        zk, rk = z[k], int(ids[k])
        labelled = s.use_ids and rk >= 0
        if labelled and rk in used_ids:
            forced[k] = None
            continue
        if labelled:
            used_ids.add(rk)
        slots = []
        for i, p in enumerate(parts):
            xb, V = _ref_motion_full(p["pose"], u, dt, e[i], b)

            def marginal(Hx, Q, V=V, i=i):
                A = Hx @ V
                return A @ Se[i] @ A.T + Q

            j, ll = _ref_associate(xb, p["lms"], zk, rk, s, seen[i], marginal)
            p["logw"] += ll
            if j >= 0:
                nu, Hx, _, Q = innovation_unchecked(xb, p["lms"][j], zk)
                A = Hx @ V
                L = A @ Se[i] @ A.T + Q
                K = Se[i] @ A.T @ np.linalg.inv(L)
                e[i] = e[i] + K @ nu
                IKA = np.eye(b + 2) - K @ A
                S_new = IKA @ Se[i] @ IKA.T + K @ Q @ K.T
                Se[i] = 0.5 * (S_new + S_new.T)
                seen[i].add(j)
            slots.append(j)
        forced[k] = slots
    for i, p in enumerate(parts):
        lam, vec = np.linalg.eigh(Se[i])
        root = vec @ np.diag(np.sqrt(np.clip(lam, 0, None))) @ vec.T
        eps = e[i] + root @ draws[i]
        p["pose"], _ = _ref_motion_full(p["pose"], u, dt, eps, b)
    seen = [set() for _ in range(n)]
    updated = [set() for _ in range(n)]
    for k in _order(ids, s):
        zk, rk = z[k], int(ids[k])
        spawned = False
        for i, p in enumerate(parts):
            if forced[k] is None:
                j, ll = _ref_associate(p["pose"], p["lms"], zk, rk, s, seen[i])
                p["logw"] += ll
            else:
                j = forced[k][i]
            if j >= 0:
                _ref_ekf(p["pose"], p["lms"][j], zk)
                seen[i].add(j)
                updated[i].add(j)
            else:
                lid = rk if (s.use_ids and rk >= 0) else next_id
                spawned |= not (s.use_ids and rk >= 0)
                p["lms"].append(_ref_new(p["pose"], zk, lid))
                seen[i].add(len(p["lms"]) - 1)
        if spawned:
            next_id += 1
    for i, p in enumerate(parts):
        p["lms"] = _ref_prune(p["pose"], p["lms"], seen[i], updated[i], s)
    _ref_normalise(parts)
    return parts, next_id


def _assert_same(ps: FastSlamParticles, parts, next_id, tol=1e-12):
    assert ps.next_id == next_id
    for i, p in enumerate(parts):
        np.testing.assert_allclose(ps.poses[i], p["pose"], rtol=0, atol=tol)
        assert abs(ps.log_weights[i] - p["logw"]) <= tol * max(1.0, abs(p["logw"]))
        n = int(ps.counts[i])
        assert n == len(p["lms"]), f"particle {i}: {n} landmarks, reference {len(p['lms'])}"
        for j, lm in enumerate(p["lms"]):
            assert ps.ids[i, j] == lm["id"]
            assert ps.counters[i, j] == lm["counter"]
            np.testing.assert_allclose(ps.means[i, j], lm["mu"], rtol=0, atol=tol)
            np.testing.assert_allclose(ps.covs[i, j], lm["cov"], rtol=0, atol=tol)


# --------------------------------------------------------------------------------------------
# A particle set with varied maps, and a scan that exercises every branch
# --------------------------------------------------------------------------------------------

TRUE_POSE = np.array([1.0, 2.0, 0.3])
WORLD = {  # id -> position; 100 and 101 were started by unlabelled readings
    0: (4.0, 3.0),
    1: (2.0, 6.0),
    2: (-1.0, 4.0),
    3: (5.0, -1.0),
    100: (3.5, 0.5),
    101: (0.0, 0.0),
    102: (2.5, 3.5),
}


def _particles(rng: np.random.Generator, n: int = 40, capacity: int = 4) -> FastSlamParticles:
    ps = FastSlamParticles.start(
        TRUE_POSE + rng.normal(0.0, [0.15, 0.15, 0.05], (n, 3)), capacity, next_id=103
    )
    cap = max(capacity, len(WORLD))
    means = np.zeros((n, cap, 2))
    covs = np.zeros((n, cap, 2, 2))
    counters = np.zeros((n, cap), dtype=np.int64)
    ids = np.full((n, cap), -1, dtype=np.int64)
    counts = np.zeros(n, dtype=np.int64)
    keys = list(WORLD)
    for p in range(n):
        chosen = rng.permutation(keys)[: rng.integers(3, len(keys) + 1)]
        for j, k in enumerate(chosen):
            means[p, j] = np.array(WORLD[int(k)]) + rng.normal(0.0, 0.1, 2)
            a = rng.normal(0.0, 0.15, (2, 2))
            covs[p, j] = a @ a.T + 0.01 * np.eye(2)
            counters[p, j] = rng.integers(0, 3)
            ids[p, j] = k
        counts[p] = chosen.size
    lw = rng.normal(0.0, 1.0, n)
    return FastSlamParticles(
        ps.poses, lw - np.log(np.exp(lw).sum()), means, covs, counters, ids, counts, 103
    )


def _scan(rng: np.random.Generator, pose=TRUE_POSE):
    """Labelled 0 and 1, unlabelled 2 and 100, a new labelled 7, unlabelled clutter, and a
    second reading of id 0."""
    model = RangeBearing()
    world = {**WORLD, 7: (0.5, -2.0), -1: (6.0, 7.0)}
    order = [(0, 0), (1, 1), (2, -1), (100, -1), (7, 7), (-1, -1), (0, 0)]
    z = np.array([model.predict(pose, world[k]) for k, _ in order])
    z += rng.normal(0.0, [0.1, 0.03], z.shape)
    return z, np.array([rid for _, rid in order], dtype=np.int64)


SETTINGS = UpdateSettings(
    p0=default_p0(R, 0.999),
    use_ids=True,
    prune=True,
    visible_min_range=0.3,
    visible_max_range=4.0,
    fov=np.deg2rad(240.0),
    first_unlabelled_id=FIRST_UNLABELLED,
)


@pytest.mark.parametrize("use_ids", [True, False])
def test_fastslam1_update_equals_per_particle_reference(use_ids: bool) -> None:
    rng = np.random.default_rng(7)
    ps = _particles(rng)
    z, ids = _scan(rng)
    s = UpdateSettings(**{**SETTINGS.__dict__, "use_ids": use_ids})
    new, ll = fastslam1_update(ps, z, ids, RangeBearing(), R, s)
    parts, next_id = ref_update1(ps, z, ids, s)
    _assert_same(new, parts, next_id)
    # Every branch ran: the capacity doubled, unlabelled landmark 102 (visible, never read)
    # was removed where its counter was 0 and kept where it was higher.
    assert (ps.capacity, new.capacity) == (7, 14)
    had_102 = [
        (p, int(ps.counters[p][ps.ids[p] == 102][0]))
        for p in range(len(ps))
        if 102 in ps.ids[p, : ps.counts[p]]
    ]
    assert {c for _, c in had_102} == {0, 1, 2}
    for p, c in had_102:
        assert (102 in new.ids[p, : new.counts[p]]) == (c > 0)
    assert ll.shape == (len(ps),) and np.all(np.isfinite(ll))
    # The input was not modified.
    again = _particles(np.random.default_rng(7))
    np.testing.assert_array_equal(ps.counts, again.counts)
    np.testing.assert_array_equal(ps.means, again.means)


@pytest.mark.parametrize("use_ids", [True, False])
def test_fastslam2_update_equals_per_particle_reference(use_ids: bool) -> None:
    rng = np.random.default_rng(11)
    ps = _particles(rng)
    u, dt = np.array([1.0, 0.2]), 0.5
    z, ids = _scan(rng, UnicycleEuler().apply(TRUE_POSE, u, dt))
    s = UpdateSettings(**{**SETTINGS.__dict__, "use_ids": use_ids})
    new, _ = fastslam2_update(
        ps, u, dt, UnicycleEuler(), Q_U, z, ids, RangeBearing(), R, s, np.random.default_rng(5)
    )
    draws = np.random.default_rng(5).standard_normal((len(ps), 2))
    parts, next_id = ref_update2(ps, u, dt, z, ids, s, draws)
    _assert_same(new, parts, next_id)


@pytest.mark.parametrize("use_ids", [True, False])
def test_fastslam2_update_with_uncertain_poses_equals_per_particle_reference(
    use_ids: bool,
) -> None:
    """With ``pose_cov`` (the motion since the last scan before this control) the proposal
    is over (pose error, control noise), 5-D here; the kernels agree with the loop."""
    rng = np.random.default_rng(13)
    ps = _particles(rng)
    u, dt = np.array([1.0, 0.2]), 0.5
    z, ids = _scan(rng, UnicycleEuler().apply(TRUE_POSE, u, dt))
    a = rng.normal(0.0, 0.1, (len(ps), 3, 3))
    pose_cov = a @ np.swapaxes(a, -1, -2) + np.diag([1e-3, 1e-3, 1e-4])
    s = UpdateSettings(**{**SETTINGS.__dict__, "use_ids": use_ids})
    new, _ = fastslam2_update(ps, u, dt, UnicycleEuler(), Q_U, z, ids, RangeBearing(), R, s,
                              np.random.default_rng(5), pose_cov=pose_cov)  # fmt: skip
    draws = np.random.default_rng(5).standard_normal((len(ps), 5))
    parts, next_id = ref_update2(ps, u, dt, z, ids, s, draws, pose_cov)
    _assert_same(new, parts, next_id)


def _common_particles(rng: np.random.Generator, n: int = 30) -> FastSlamParticles:
    """Labelled landmarks only, in the same slots in every particle (the fast path)."""
    ps = _particles(rng, n)
    keys = [0, 1, 2, 3]
    means = np.zeros((n, 4, 2))
    for j, k in enumerate(keys):
        means[:, j] = np.array(WORLD[k]) + rng.normal(0.0, 0.1, (n, 2))
    covs = np.broadcast_to(np.diag([0.02, 0.03]), (n, 4, 2, 2)).copy()
    return FastSlamParticles(
        ps.poses, ps.log_weights, means, covs, np.ones((n, 4), dtype=np.int64),
        np.tile(np.array(keys), (n, 1)), np.full(n, 4), 103,
    )  # fmt: skip


def test_fastslam1_common_layout_fast_path_equals_reference() -> None:
    rng = np.random.default_rng(3)
    ps = _common_particles(rng)
    z, ids = _scan(rng)
    new, _ = fastslam1_update(ps, z, ids, RangeBearing(), R, SETTINGS)
    _assert_same(new, *ref_update1(ps, z, ids, SETTINGS))
    # Landmark 7 was started everywhere; labelled landmarks keep no existence counter.
    assert np.all(new.ids[:, 4] == 7) and np.all(new.counters[:, :5] == ps.counters[0, 0])


@pytest.mark.parametrize("model", [RangeBearing(), RelativePosition()])
def test_landmark_terms_equal_the_models_methods(model) -> None:
    """The fused planar kernel (range-bearing written out, other models through their batch
    kernels) against ``predict``/``jacobians`` and dense 2×2 algebra, to 1e-12; a landmark
    at the sensor is flagged."""
    from slamkit.slam.fastslam.kernels import landmark_terms
    from slamkit.slam.fastslam.store import H00, I00, LOGDET, T00, ZH0

    rng = np.random.default_rng(4)
    poses = rng.normal(0.0, [2.0, 2.0, 2.0], (7, 3))
    mu = rng.uniform(-6.0, 6.0, (3, 7, 2))
    mu[1, 2] = poses[2, :2]  # at the sensor
    a = rng.normal(0.0, 0.2, (3, 7, 2, 2))
    cov = a @ np.swapaxes(a, -1, -2) + 0.01 * np.eye(2)
    g = np.stack([mu[..., 0], mu[..., 1], cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]])
    Rm = np.array([[0.02, 0.003], [0.003, 0.01]])
    F, ok = landmark_terms(model, tuple(poses.T), g, Rm)
    assert ok.tolist() == [[True] * 7, [True, True, False] + [True] * 4, [True] * 7]
    keep = ok
    safe = mu.copy()
    safe[1, 2] += 1.0  # the models' methods raise at the sensor: compared where ok only
    z_hat = model.predict(poses[None], safe)
    Hm = model.jacobians(poses[None], safe)[1]
    T = Hm @ cov
    Q = T @ np.swapaxes(Hm, -1, -2) + Rm
    got_z = np.stack([F[ZH0], F[ZH0 + 1]], -1)
    d = got_z - z_hat
    d[..., 1] = (d[..., 1] + np.pi) % (2 * np.pi) - np.pi if model.angular[1] else d[..., 1]
    np.testing.assert_allclose(d[keep], 0.0, atol=1e-12)
    got_H = np.stack([F[H00 : H00 + 2], F[H00 + 2 : H00 + 4]]).transpose(2, 3, 0, 1)
    np.testing.assert_allclose(got_H[keep], Hm[keep], rtol=0, atol=1e-12)
    got_T = np.stack([F[T00 : T00 + 2], F[T00 + 2 : T00 + 4]]).transpose(2, 3, 0, 1)
    np.testing.assert_allclose(got_T[keep], T[keep], rtol=0, atol=1e-12)
    Qi = np.linalg.inv(Q)
    np.testing.assert_allclose(F[I00][keep], Qi[..., 0, 0][keep], rtol=1e-12)
    np.testing.assert_allclose(F[I00 + 1][keep], Qi[..., 0, 1][keep], rtol=1e-12)
    np.testing.assert_allclose(F[I00 + 2][keep], Qi[..., 1, 1][keep], rtol=1e-12)
    np.testing.assert_allclose(F[LOGDET][keep], np.log(np.linalg.det(Q))[keep], atol=1e-12)


# --------------------------------------------------------------------------------------------
# Resampling, capacity, weights, errors
# --------------------------------------------------------------------------------------------


def test_resampling_copies_maps_without_aliasing() -> None:
    ps = _particles(np.random.default_rng(1), n=6)
    out = ps.select(np.array([2, 2, 2, 0, 5, 5]))
    assert not np.shares_memory(out.means, ps.means)
    assert not np.shares_memory(out.covs, ps.covs)
    np.testing.assert_array_equal(out.means[0], out.means[1])
    before = ps.means.copy()
    out.means[0, 0] += 5.0  # move one resampled particle's landmark
    out.covs[0, 0] *= 3.0
    out.ids[0, 0] = 999
    np.testing.assert_array_equal(out.means[1], ps.means[2])  # its twin did not move
    np.testing.assert_array_equal(out.covs[2], ps.covs[2])
    assert out.ids[1, 0] == ps.ids[2, 0] != 999
    np.testing.assert_array_equal(ps.means, before)  # nor did the original
    np.testing.assert_allclose(out.weights, 1.0 / 6.0)
    # The same through low-variance resampling of a skewed set.
    lw = np.log(np.array([1e-9, 1e-9, 0.5, 1e-9, 1e-9, 0.5]))
    skewed = FastSlamParticles(ps.poses, lw - np.log(np.exp(lw).sum()), ps.means, ps.covs,
                               ps.counters, ps.ids, ps.counts, ps.next_id)  # fmt: skip
    res = fastslam_resample(skewed, np.random.default_rng(0))
    assert set(np.unique(res.ids[:, 0]).tolist()) <= {ps.ids[2, 0], ps.ids[5, 0]}
    res.means[0] += 1.0
    assert not np.any(np.all(res.means[1:] == res.means[0], axis=(1, 2)))


def test_capacity_doubles_and_keeps_the_landmarks() -> None:
    ps = FastSlamParticles.start(np.tile(TRUE_POSE, (3, 1)), capacity=1)
    lms = np.array([[3.0, 2.0], [1.0, 5.0], [-2.0, 2.5], [4.0, 4.0], [0.0, -1.0]])
    z = RangeBearing().predict(TRUE_POSE, lms)
    s = UpdateSettings(p0=default_p0(R))
    out, ll = fastslam1_update(ps, z[:2], [10, 11], RangeBearing(), R, s)
    assert out.capacity == 2 and out.counts.tolist() == [2, 2, 2]
    out, _ = fastslam1_update(out, z[2:], [12, 13, 14], RangeBearing(), R, s)
    assert out.capacity == 8 and out.counts.tolist() == [5, 5, 5]
    np.testing.assert_allclose(out.means[:, :5], np.broadcast_to(lms, (3, 5, 2)), atol=1e-12)
    assert out.landmarks_of(1).landmarks.ids.tolist() == [10, 11, 12, 13, 14]
    np.testing.assert_allclose(ll, 2 * np.log(s.p0))  # new landmarks: p0 each


def test_weight_underflow_is_normalised_in_log_space() -> None:
    """Every particle's likelihood underflows float64 (log ~ -1e5); the weights still
    normalise and the best particle is the one that explains the reading best."""
    n = 5
    poses = np.tile([0.0, 0.0, 0.0], (n, 1))
    means = np.zeros((n, 1, 2))
    means[:, 0, 0] = 10.0
    means[:, 0, 1] = np.array([30.0, 10.0, 20.0, 40.0, 50.0])  # particle 1: the nearest
    covs = np.broadcast_to(1e-6 * np.eye(2), (n, 1, 2, 2)).copy()
    ps = FastSlamParticles(poses, np.full(n, -np.log(n)), means, covs,
                           np.ones((n, 1), dtype=np.int64), np.zeros((n, 1), dtype=np.int64),
                           np.ones(n, dtype=np.int64))  # fmt: skip
    z = RangeBearing().predict(poses[0], [10.0, 0.0])[None, :]
    out, ll = fastslam1_update(ps, z, [0], RangeBearing(), R, UpdateSettings(p0=1e-3))
    assert np.all(ll < -1e3) and np.all(np.exp(ll) == 0.0)  # underflow in linear space
    w = out.weights
    assert np.isfinite(out.log_weights[out.best]) and out.best == 1
    assert w.sum() == pytest.approx(1.0) and w[1] == pytest.approx(1.0)
    # All weights zero: no normalisation exists -> ConvergenceError, never a silent reset.
    dead = FastSlamParticles(poses, np.full(n, -np.inf), means, covs, ps.counters, ps.ids,
                             ps.counts)  # fmt: skip
    with pytest.raises(ConvergenceError, match="zero"):
        fastslam1_update(dead, z, [0], RangeBearing(), R, UpdateSettings(p0=1e-3))


def test_estimator_raises_convergence_error_with_the_step() -> None:
    """The robot drives exactly onto the landmark it mapped: every particle's likelihood of
    the next reading is zero (no bearing at zero range) -> ConvergenceError. Its step is the
    runner's (one per distinct time stamp, as EKF-SLAM's): the fourth time stamp, though it
    is only the second measurement update."""
    events = (
        LandmarkReadings(0.0, np.array([[1.0, 0.0]]), np.array([0])),
        Control(1.0, np.array([1.0, 0.0]), 1.0),
        Control(1.5, np.array([0.0, 0.0]), 0.5),
        Control(2.0, np.array([0.0, 0.0]), 0.5),
        LandmarkReadings(2.0, np.array([[0.5, 0.0]]), np.array([0])),
    )
    ds = Dataset("onto-landmark", events, motion=MotionSpec(UnicycleEuler(), np.zeros((2, 2))),
                 landmark_sensor=LandmarkSensorSpec("range-bearing", R),
                 initial_pose=np.zeros(3), initial_cov=np.zeros((3, 3)))  # fmt: skip
    for v in (1, 2):
        with pytest.raises(ConvergenceError, match="measurement update 2") as info:
            run(ENTRIES[v], ds, config={"n_particles": 4}, seed=0)
        assert info.value.step == 4


def test_bad_inputs_raise_typed_errors() -> None:
    ps = _particles(np.random.default_rng(0), n=4)
    z, ids = _scan(np.random.default_rng(0))
    bad_z = z.copy()
    bad_z[1, 0] = np.nan
    with pytest.raises(NonFiniteError):
        fastslam1_update(ps, bad_z, ids, RangeBearing(), R, SETTINGS)
    with pytest.raises(CovarianceError):
        fastslam1_update(ps, z, ids, RangeBearing(), [[0.01, 0.02], [0.02, 0.01]], SETTINGS)
    with pytest.raises(CovarianceError):
        fastslam2_update(ps, [1.0, 0.0], 0.1, UnicycleEuler(), [[1.0, 0.0], [0.0, -1.0]], z,
                         ids, RangeBearing(), R, SETTINGS, np.random.default_rng(0))  # fmt: skip
    with pytest.raises(InputError, match="inverse"):
        fastslam1_update(ps, z[:, :1], ids, RangeOnly(), [[0.01]], SETTINGS)
    with pytest.raises(ConfigError):
        FastSlamConfig(n_particles=0)
    with pytest.raises(ConfigError):
        FastSlamConfig(p0=-1.0)
    with pytest.raises(ConfigError):
        UpdateSettings(p0=0.0)
    ds = load_dataset("five-features-range", seed=0)
    with pytest.raises(InputError, match="range"):
        FastSlam1(ds, FastSlamConfig(), np.random.default_rng(0))
    # NaN readings never reach an estimator: the data set rejects them at construction.
    with pytest.raises(NonFiniteError):
        Dataset("nan", (LandmarkReadings(0.0, bad_z, ids),),
                landmark_sensor=LandmarkSensorSpec("range-bearing", R))  # fmt: skip


# --------------------------------------------------------------------------------------------
# The unchecked hot-path kernels against the validated functions
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "model",
    [
        UnicycleEuler(),
        UnicycleArc(),
        OdometryModel(),
        Ackermann(2.83, (0.4, -0.2), 0.76),
        DifferentialDrive(0.5),
    ],
    ids=lambda m: type(m).__name__,
)
def test_move_particles_in_place_equals_apply(model) -> None:
    """The in-place particle kernel of every motion model against ``apply`` (1e-12; it is
    bit-identical), with headings near ±π so that some wrap and some do not, a straight
    (ω = 0) control for the arc's series branch and turns only for its closed form, and
    the input controls left alone."""
    rng = np.random.default_rng(3)
    n = 200
    near_pi = rng.choice([-1.0, 1.0], n) * (np.pi - rng.uniform(0, 0.05, n))
    x = np.column_stack([rng.normal(0, 5, n), rng.normal(0, 5, n), near_pi])
    k = model.control_dim
    u = rng.normal(0.0, 0.3, (n, k)) + (np.array([1.0, 0.2, 0.1])[:k])
    u[0, -1] = 0.0
    u_copy = u.copy()
    for dt in (0.1, 0.0):
        want = model.apply(x, u, dt)
        got = x.copy()
        model.move_particles(got, u, dt)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        assert np.all((got[:, 2] >= -np.pi) & (got[:, 2] < np.pi))
    np.testing.assert_array_equal(u, u_copy)
    # No heading out of range: the same, without the wrap; and every turn rate away from 0
    # (the arc's closed form only).
    x[:, 2] = rng.uniform(-1.0, 1.0, n)
    turning = u.copy()
    turning[:, -1] = np.clip(np.where(u[:, -1] < 0, -0.5, 0.5) + u[:, -1], -1.0, 1.0)
    for controls in (u, turning):
        got = x.copy()
        model.move_particles(got, controls, 0.1)
        np.testing.assert_allclose(got, model.apply(x, controls, 0.1), rtol=0, atol=1e-12)


def test_ackermann_max_steering_is_the_models_domain() -> None:
    """``max_steering``: ``min(π/2, atan(L/|H|))``; the model is defined just inside it (in
    both directions) and raises at it."""
    car = Ackermann(2.83, (0.0, 0.0), 0.76)
    assert car.max_steering == pytest.approx(math.atan(2.83 / 0.76))
    assert Ackermann(2.0).max_steering == pytest.approx(np.pi / 2)
    x = np.zeros(3)
    for sign in (1.0, -1.0):
        assert np.all(np.isfinite(car.apply(x, [1.0, sign * 0.999 * car.max_steering], 0.1)))
    with pytest.raises(GeometryError):
        car.apply(x, [1.0, car.max_steering * (1 + 1e-9)], 0.1)


def test_unchecked_low_variance_resample_equals_the_validated_one() -> None:
    rng = np.random.default_rng(4)
    for n in (1, 7, 100):
        w = rng.exponential(1.0, n)
        w[rng.random(n) < 0.3] = 0.0
        w[0] = max(w[0], 1e-3)
        w /= w.sum()
        a, b = np.random.default_rng(9), np.random.default_rng(9)
        np.testing.assert_array_equal(
            low_variance_resample_unchecked(w, a, n), low_variance_resample(w, b)
        )
        assert a.bit_generator.state == b.bit_generator.state


# --------------------------------------------------------------------------------------------
# FastSLAM 2.0's proposal against brute-force importance sampling
# --------------------------------------------------------------------------------------------


def test_fastslam2_posterior_matches_fastslam1_with_many_particles() -> None:
    """One step from a known pose, two sharply measured landmarks, broad motion noise:
    2.0's weighted particles and 1.0's (brute-force importance sampling, 200 000 particles)
    estimate the same posterior; 2.0 needs no resampling to do so (ESS = P)."""
    Rs = np.diag([0.05**2, np.deg2rad(1.0) ** 2])
    Qu = np.diag([0.15**2, 0.08**2])
    u, dt = np.array([1.0, 0.1]), 1.0
    lm = np.array([[3.0, 1.0], [1.5, -2.0]])
    x_true = UnicycleEuler().apply([0.0, 0.0, 0.0], u + np.array([0.1, -0.05]), dt)
    z = RangeBearing().predict(x_true, lm)

    def start(n: int) -> FastSlamParticles:
        return FastSlamParticles(
            np.zeros((n, 3)), np.full(n, -np.log(n)), np.broadcast_to(lm, (n, 2, 2)).copy(),
            np.broadcast_to(1e-4 * np.eye(2), (n, 2, 2, 2)).copy(),
            np.ones((n, 2), dtype=np.int64), np.tile([0, 1], (n, 1)), np.full(n, 2),
        )  # fmt: skip

    s = UpdateSettings(p0=1e-3)
    rng = np.random.default_rng(0)
    moved = fastslam_predict(start(200_000), u, dt, UnicycleEuler(), Qu, rng)
    one, _ = fastslam1_update(moved, z, [0, 1], RangeBearing(), Rs, s)
    two, _ = fastslam2_update(start(20_000), u, dt, UnicycleEuler(), Qu, z, [0, 1],
                              RangeBearing(), Rs, s, rng)  # fmt: skip
    m1, c1 = particle_estimate(one.poses, one.weights)
    m2, c2 = particle_estimate(two.poses, two.weights)
    sd = np.sqrt(np.diag(c1))[[0, 2]]  # y stays 0: the Euler step keeps the start heading
    assert np.all(np.abs(m2 - m1)[[0, 2]] < 0.1 * sd)  # measured 0.03 and 0.04 sd
    np.testing.assert_allclose(np.sqrt(np.diag(c2))[[0, 2]], sd, rtol=0.05)
    assert effective_sample_size(two.weights) == pytest.approx(20_000)
    assert effective_sample_size(one.weights) < 0.1 * 200_000  # 1.0: ~4 % of P


@pytest.mark.parametrize("uncertain_start", [False, True])
def test_fastslam2_odometry_proposal_matches_brute_force(uncertain_start: bool) -> None:
    """The cityTrees case: odometry controls with correlated noise (cov(rot1, rot2) < 0, the
    loader's values), robot-frame position readings of three landmarks, σ = 0.1 m. With the
    start pose exact, and with it uncertain by ``pose_cov`` (the motion since the last scan,
    which the estimator folds in when several controls precede a scan): 2.0's weighted
    particles have the moments of brute-force importance sampling (start poses drawn from
    ``N(x0, pose_cov)``, then 1.0 with 400 000 particles), and its weight is the brute-force
    marginal likelihood ``log mean p(z | x)``. Measured: means within 0.015 sd, spreads
    within 1 %, log-likelihoods within 0.006 (the bounds are 10x that: Monte Carlo noise).
    Proposing from the last control alone with the start pose taken as exact (what the
    estimator did before it folded earlier controls in) is 0.7 sd off in y and θ here, with
    40-80 % of the spread."""
    Qu = np.array([[4e-4, 0.0, -4e-4], [0.0, 4e-4, 0.0], [-4e-4, 0.0, 5e-4]])
    Px = np.array([[4e-3, 1e-3, -5e-4], [1e-3, 2e-3, 8e-4], [-5e-4, 8e-4, 1e-3]])
    if not uncertain_start:
        Px = np.zeros((3, 3))
    Rs = np.diag([0.1**2, 0.1**2])
    u = np.array([0.02, 1.0, 0.01])
    lm = np.array([[5.0, 3.0], [2.0, -7.0], [7.5, 0.5]])
    x0 = np.array([0.0, 0.0, 0.3])
    model, sensor = OdometryModel(), RelativePosition()
    x_true = model.apply(x0 + np.array([0.05, -0.03, 0.02]), u + np.array([0.03, -0.02, -0.03]))
    z = sensor.predict(x_true, lm)

    def start(poses: np.ndarray) -> FastSlamParticles:
        n = poses.shape[0]
        return FastSlamParticles(
            poses, np.full(n, -np.log(n)), np.broadcast_to(lm, (n, 3, 2)).copy(),
            np.broadcast_to(1e-3 * np.eye(2), (n, 3, 2, 2)).copy(),
            np.ones((n, 3), dtype=np.int64), np.tile([0, 1, 2], (n, 1)), np.full(n, 3),
        )  # fmt: skip

    s = UpdateSettings(p0=1e-3)
    rng = np.random.default_rng(0)
    n1 = 400_000
    prev = x0 + rng.standard_normal((n1, 3)) @ np.linalg.cholesky(Px + 1e-15 * np.eye(3)).T
    moved = fastslam_predict(start(prev), u, 0.0, model, Qu, rng)
    one, ll1 = fastslam1_update(moved, z, [0, 1, 2], sensor, Rs, s)
    two, ll2 = fastslam2_update(start(np.tile(x0, (20_000, 1))), u, 0.0, model, Qu, z,
                                [0, 1, 2], sensor, Rs, s, rng,
                                pose_cov=Px if uncertain_start else None)  # fmt: skip
    m1, c1 = particle_estimate(one.poses, one.weights)
    m2, c2 = particle_estimate(two.poses, two.weights)
    sd = np.sqrt(np.diag(c1))
    assert np.all(np.abs(m2 - m1) < 0.1 * sd)
    np.testing.assert_allclose(np.sqrt(np.diag(c2)), sd, rtol=0.05)
    log_marginal = float(np.log(np.mean(np.exp(ll1 - ll1.max()))) + ll1.max())
    np.testing.assert_allclose(ll2, log_marginal, atol=0.06)
    assert effective_sample_size(two.weights) == pytest.approx(20_000)


# --------------------------------------------------------------------------------------------
# The estimators on simulated worlds
# --------------------------------------------------------------------------------------------


def _run(version: int, data: str, seed: int, options=None, **config):
    ds = load_dataset(data, seed=seed, options=options or {})
    return ds, run(ENTRIES[version], ds, config=config, seed=seed)


def _ate(result, ds) -> float:
    return absolute_trajectory_error(result.poses, ds.truth.poses, align="se2").rmse


@pytest.mark.parametrize("version", [1, 2])
def test_converges_in_the_five_feature_world(version: int) -> None:
    """Known ids, 50 particles, seed 0. Measured (seeds 0-2): 1.0 ATE 0.042/0.044/0.098 m,
    landmark RMSE 0.030/0.020/0.032 m; 2.0 ATE 0.076/0.050/0.048, landmarks 0.022/0.022/
    0.020."""
    ds, res = _run(version, "five-features", 0, n_particles=50)
    assert len(res) == len(ds.truth.poses)
    assert _ate(res, ds) < 0.12
    lm = res.output.landmarks
    assert lm is not None and lm.covariances is not None
    assert lm.landmarks.ids.tolist() == [0, 1, 2, 3, 4]
    err = landmark_map_error(lm.landmarks, ds.truth.landmarks)
    assert err.rmse < 0.06 and err.max < 0.1
    d = res.output.diagnostics
    assert d["version"] == version and d["landmarks"] == 5 and d["resamplings"] > 0
    assert 1.0 <= d["ess_min"] <= d["ess_mean"] <= 50.0
    assert np.all(np.linalg.eigvalsh(lm.covariances) > 0)


def _matched_map_error(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Distances after matching estimated to true landmarks one-to-one (Hungarian) and
    aligning the matched sets (unlabelled landmarks have ids of their own)."""
    d = np.linalg.norm(estimate[:, None, :] - truth[None, :, :], axis=2)
    r, c = linear_sum_assignment(d)
    aligned = align_points_2d(estimate[r], truth[c]).apply_to_points(estimate[r])
    return np.linalg.norm(aligned - truth[c], axis=1)


@pytest.mark.parametrize("version", [1, 2])
def test_unknown_association_in_the_five_feature_world(version: int) -> None:
    """Readings without ids: every particle associates by maximum likelihood. Measured with
    50 particles over seeds 0-5 (default p0): always exactly 5 landmarks; 1.0 ATE <= 0.088 m,
    landmark RMSE <= 0.045 m; 2.0 ATE <= 0.076, landmarks <= 0.031. (With
    new_landmark_probability 0.999 four of those twelve runs kept a duplicate of the first
    landmark at the loop closure.)"""
    for seed in (0, 1):
        ds, res = _run(version, "five-features", seed, {"identities": False}, n_particles=50)
        lm = res.output.landmarks
        assert lm is not None and len(lm.landmarks) == 5
        assert np.all(lm.landmarks.ids >= 0)
        err = _matched_map_error(lm.landmarks.positions, ds.truth.landmarks.positions)
        assert err.max() < 0.12, err
        assert _ate(res, ds) < 0.15


def test_clutter_is_pruned_by_existence_counters() -> None:
    """Every fifth scan carries one clutter reading (uniform in range and bearing): each
    starts a landmark, is never seen again, and is removed once predicted visible and missed
    twice; the final map holds just the five landmarks."""
    ds = load_dataset("five-features", seed=2, options={"identities": False})
    rng = np.random.default_rng(0)
    events, n_clutter = [], 0
    true_ids = list(ds.truth.reading_ids or ())
    scan = 0
    for i, ev in enumerate(ds.events):
        if isinstance(ev, LandmarkReadings):
            if i % 5 == 0 and ev.t < 25.0:
                junk = np.array([[rng.uniform(1.0, 7.0), rng.uniform(-np.pi, np.pi)]])
                ev = LandmarkReadings(ev.t, np.vstack([ev.z, junk]), np.append(ev.ids, -1))
                if true_ids:
                    true_ids[scan] = np.append(true_ids[scan], -1)
                n_clutter += 1
            scan += 1
        events.append(ev)
    truth = dataclasses.replace(ds.truth, reading_ids=tuple(true_ids) if true_ids else None)
    cluttered = dataclasses.replace(ds, events=tuple(events), truth=truth)
    res = run(ENTRIES[1], cluttered, config={"n_particles": 30}, seed=2)
    d = res.output.diagnostics
    assert n_clutter > 20
    assert d["landmarks"] == 5 and d["landmarks_max"] == 5
    assert d["landmarks_removed"] >= 20 * 30  # every clutter landmark, in every particle
    assert res.output.landmarks is not None
    err = _matched_map_error(res.output.landmarks.landmarks.positions,
                             ds.truth.landmarks.positions)  # fmt: skip
    assert err.max() < 0.12


def test_fastslam2_beats_fastslam1_with_few_particles() -> None:
    """20 particles, noisy motion (0.3 m/s, 20°/s) and a precise sensor (5 cm, 1°): the
    proposal that includes the readings keeps ~3x the effective sample size and a better
    map. Measured over seeds 0-11: landmark RMSE 0.023 (1.0) vs 0.014 m (2.0), mean ESS 4.2
    vs 12.6; here seeds 0-3."""
    opts = {"sigma_v": 0.3, "sigma_omega_deg": 20.0, "sigma_range": 0.05,
            "sigma_bearing_deg": 1.0}  # fmt: skip
    lm_err = {1: [], 2: []}
    ess = {1: [], 2: []}
    for seed in range(4):
        ds = load_dataset("five-features", seed=seed, options=opts)
        for v in (1, 2):
            res = run(ENTRIES[v], ds, config={"n_particles": 20}, seed=100 + seed)
            assert res.output.landmarks is not None
            lm_err[v].append(landmark_map_error(res.output.landmarks.landmarks,
                                                ds.truth.landmarks).rmse)  # fmt: skip
            ess[v].append(res.output.diagnostics["ess_mean"])
    assert np.mean(lm_err[2]) < 0.9 * np.mean(lm_err[1])
    assert np.mean(ess[2]) > 2.0 * np.mean(ess[1])


@pytest.mark.parametrize("version", [1, 2])
def test_same_seed_same_numbers(version: int) -> None:
    ds = load_dataset("five-features", seed=4, options={"identities": False})
    a = run(ENTRIES[version], ds, config={"n_particles": 15}, seed=9)
    b = run(ENTRIES[version], ds, config={"n_particles": 15}, seed=9)
    c = run(ENTRIES[version], ds, config={"n_particles": 15}, seed=10)
    np.testing.assert_array_equal(a.poses, b.poses)
    np.testing.assert_array_equal(a.covariances, b.covariances)
    assert a.output.landmarks is not None and b.output.landmarks is not None
    np.testing.assert_array_equal(a.output.landmarks.landmarks.positions,
                                  b.output.landmarks.landmarks.positions)  # fmt: skip
    assert a.output.diagnostics == b.output.diagnostics
    assert not np.array_equal(a.poses, c.poses)


def test_fastslam2_holds_a_control_until_its_scan() -> None:
    ds = load_dataset("five-features", seed=0)
    rng = np.random.default_rng(0)
    est = FastSlam2(ds, FastSlamConfig(n_particles=10), rng)
    control = next(ev for ev in ds.events if isinstance(ev, Control))
    before = est.particles.poses.copy()
    state = rng.bit_generator.state
    est.handle(control)  # nothing is drawn until the scan (or the next control) arrives
    np.testing.assert_array_equal(est.particles.poses, before)
    assert rng.bit_generator.state == state
    moved = UnicycleEuler().apply(before, control.u, control.dt)
    expected = particle_estimate(moved, est.particles.weights)[0]
    np.testing.assert_allclose(est.estimate().pose, expected, rtol=0, atol=1e-12)
    assert rng.bit_generator.state == state  # estimate() draws nothing either


def test_fastslam2_folds_every_control_before_a_scan_into_its_proposal() -> None:
    """Several controls before a scan: none is sampled; each particle carries the motion
    since its scan as a Gaussian (EKF predictions, :func:`propagate_gaussian`), the estimate
    is the mixture of those Gaussians, and the scan's proposal starts from it."""
    ds = load_dataset("five-features", seed=0)
    rng = np.random.default_rng(0)
    est = FastSlam2(ds, FastSlamConfig(n_particles=10), rng)
    controls = [ev for ev in ds.events if isinstance(ev, Control)][:3]
    before = est.particles.poses.copy()
    state = rng.bit_generator.state
    for ev in controls:
        est.handle(ev)
    assert rng.bit_generator.state == state
    np.testing.assert_array_equal(est.particles.poses, before)
    mean, cov = before, np.zeros((10, 3, 3))
    for ev in controls:
        mean, cov = propagate_gaussian(UnicycleEuler(), mean, cov, ev.u, ev.dt, ds.motion.noise_cov)
    w = est.particles.weights
    m, c = particle_estimate(mean, w)
    got = est.estimate()
    np.testing.assert_allclose(got.pose, m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.cov, c + np.einsum("p,pij->ij", w, cov), rtol=0, atol=1e-12)
    scan = next(
        ev for ev in ds.events if isinstance(ev, LandmarkReadings) and ev.t > controls[-1].t
    )
    est.handle(scan)  # the proposal: (pose error, control noise), 3 + 2 normals per particle
    ref = np.random.default_rng(0)
    ref.bit_generator.state = state
    ref.standard_normal((10, 5))
    assert rng.bit_generator.state == ref.bit_generator.state


@pytest.mark.parametrize("version", [1, 2])
def test_odometry_events_and_position_readings(version: int) -> None:
    """The other motion source and sensor kind: Odometry poses (noisy chain) and (x, y)
    readings in the robot frame, as in the iSAM cityTrees data set."""
    ds = load_dataset("five-features", seed=1)
    truth, world = ds.truth.poses, ds.truth.landmarks
    assert truth is not None and world is not None
    rng = np.random.default_rng(5)
    q = np.diag([np.deg2rad(0.5) ** 2, 0.02**2, np.deg2rad(0.5) ** 2])
    model = OdometryModel()
    sensor = LandmarkSensorSpec("position", np.diag([0.05**2, 0.05**2]), max_range=8.0)
    odom = [truth[0]]
    events: list = []
    for k in range(1, len(truth)):
        u = odometry_control(truth[k - 1], truth[k]) + rng.multivariate_normal(np.zeros(3), q)
        odom.append(model.apply(odom[-1], u))
    for k in range(len(truth)):
        t = float(ds.truth.times[k])
        events.append(Odometry(t, odom[k]))
        z, ids = observe_landmarks(truth[k], world, sensor, rng)
        if ids.size:
            events.append(LandmarkReadings(t, z, ids))
    data = Dataset("odometry-position", tuple(events), motion=MotionSpec(model, q, "odometry"),
                   landmark_sensor=sensor, initial_pose=truth[0], initial_cov=np.zeros((3, 3)),
                   truth=dataclasses.replace(ds.truth, reading_ids=None))  # fmt: skip
    res = run(ENTRIES[version], data, config={"n_particles": 30}, seed=0)
    assert res.output.landmarks is not None
    err = landmark_map_error(res.output.landmarks.landmarks, world)
    assert err.n_matched == 5 and err.rmse < 0.03  # measured 0.010 (1.0), 0.011 (2.0)
    odo_ate = absolute_trajectory_error(np.asarray(odom), truth, align="se2").rmse
    assert _ate(res, data) < 0.3 * odo_ate  # measured 0.033 m vs 0.29 m of odometry


@pytest.mark.parametrize("version", [1, 2])
def test_particle_snapshots_for_the_plots(version: int) -> None:
    """By default six snapshots spread over the run (the last at its end), each a copy of
    the poses with normalised weights; ``snapshot_every`` counts measurement updates (plus
    the initial set) as MCL's does; ``n_snapshots=0`` keeps none."""
    ds = load_dataset("five-features", seed=0)
    res = run(ENTRIES[version], ds, config={"n_particles": 10}, seed=0)
    snaps = res.output.particle_snapshots
    times = [s.t for s in snaps]
    assert len(snaps) == 6 and times == sorted(times)
    assert times[0] == ds.start_time and times[-1] == ds.end_time
    for s in snaps:
        assert s.particles.shape == (10, 3) and s.weights.sum() == pytest.approx(1.0)
    # The clouds follow the robot: first at the start, last near the last true pose.
    assert np.linalg.norm(snaps[0].particles.mean(axis=0)[:2] - ds.truth.poses[0, :2]) < 0.1
    assert np.linalg.norm(snaps[-1].particles.mean(axis=0)[:2] - ds.truth.poses[-1, :2]) < 0.5
    assert not np.shares_memory(snaps[-1].particles, snaps[-2].particles)
    every = run(ENTRIES[version], ds, config={"n_particles": 10, "snapshot_every": 100}, seed=0)
    updates = every.output.diagnostics["measurement_updates"]
    assert len(every.output.particle_snapshots) == 1 + updates // 100
    none = run(ENTRIES[version], ds, config={"n_particles": 10, "n_snapshots": 0}, seed=0)
    assert none.output.particle_snapshots == ()


@pytest.mark.parametrize(("version", "seeds"), [(1, (0, 1, 2)), (2, (1,))])
def test_association_accuracy_in_the_cluttered_world(version: int, seeds) -> None:
    """``landmark-clutter``: 150 landmarks >= 1.2 m apart, ~13 readings per scan, no ids, a
    loop closed at the end; the best particle's association (traced through its ancestors)
    scored against ``truth.reading_ids`` (:func:`slamkit.eval.association_scores`: the
    filter numbers its landmarks itself). Measured with 100 particles (1.0, seeds 0-5):
    accuracy 1.0, 1.0, 0.9997, 0.961, 0.9997, 0.9993 — seed 3 fails part of the loop
    closure (14 landmarks mapped twice) — and 30 particles (2.0, seeds 0-3): 0.971, 1.0,
    0.953, 0.997. The issue's target is 95 %."""
    from slamkit.eval import association_scores

    for seed in seeds:
        ds = load_dataset("landmark-clutter", seed=seed)
        assert ds.truth.reading_ids is not None
        n = 100 if version == 1 else 30
        res = run(ENTRIES[version], ds, config={"n_particles": n}, seed=seed)
        chosen = res.output.reading_landmarks
        assert chosen is not None and chosen.size == sum(a.size for a in ds.truth.reading_ids)
        scores = association_scores(chosen, np.concatenate(ds.truth.reading_ids)).as_dict()
        assert scores["accuracy"] >= 0.95, (seed, scores)  # measured >= 0.9997 for these
        assert scores["used"] == scores["readings"]  # every reading updated or started one


def test_reading_log_follows_the_best_particle_through_resampling() -> None:
    """With ids the log is the ids themselves, updated or started; without, each logged id
    is a landmark of the final best particle's map or one it started and later pruned."""
    ds = load_dataset("five-features", seed=3)
    labels = np.concatenate([e.ids for e in ds.events if isinstance(e, LandmarkReadings)])
    est = FastSlam1(ds, FastSlamConfig(n_particles=20), np.random.default_rng(0))
    for ev in ds.events:
        est.handle(ev)
    times, ids, status = est.reading_log()
    assert ids.tolist() == labels.tolist() and times.size == labels.size
    assert np.count_nonzero(status == 1) == 5 and set(status.tolist()) == {0, 1}  # 5 starts
    ds = load_dataset("five-features", seed=3, options={"identities": False})
    est = FastSlam1(ds, FastSlamConfig(n_particles=20), np.random.default_rng(0))
    for ev in ds.events:
        est.handle(ev)
    assert est.finish().diagnostics["resamplings"] > 10
    _, ids, status = est.reading_log()
    best = est.particles.best
    kept = set(est.particles.ids[best, : est.particles.counts[best]].tolist())
    assert kept <= set(ids.tolist()) and len(kept) == 5
    assert np.mean(np.isin(ids, list(kept))) > 0.99


def test_error_within_a_stated_factor_of_ekf_slam() -> None:
    """The same simulated runs (five-features, known ids, seeds 0-3) through EKF-SLAM and
    FastSLAM with 100 particles: mean ATE and landmark RMSE. Measured (seeds 0-3): EKF-SLAM
    ATE 0.041 m, landmarks 0.012 m; FastSLAM 1.0 1.31x and 1.21x those; 2.0 2.11x and 1.46x
    (its sampled poses trade a higher ESS for more pose jitter here). Over seeds 0-5 the
    ratios are 1.30/1.19 (1.0) and 2.00/1.34 (2.0). Stated factors: 1.0 within 1.5x of
    EKF-SLAM on both, 2.0 within 2.5x (ATE) and 1.75x (landmarks)."""
    ekf = EstimatorEntry(
        "ekf-slam", "EKF-SLAM", "slamkit.slam.ekf_slam:EkfSlam",
        "slamkit.slam.ekf_slam:EkfSlamConfig", requires=("motion", "landmark_sensor"),
    )  # fmt: skip
    err: dict[str, list[tuple[float, float]]] = {"ekf": [], "1": [], "2": []}
    for seed in range(4):
        ds = load_dataset("five-features", seed=seed)
        for name, entry, cfg in (("ekf", ekf, {}), ("1", ENTRIES[1], {"n_particles": 100}),
                                 ("2", ENTRIES[2], {"n_particles": 100})):  # fmt: skip
            res = run(entry, ds, config=cfg, seed=seed)
            assert res.output.landmarks is not None
            lm = landmark_map_error(res.output.landmarks.landmarks, ds.truth.landmarks)
            assert lm.n_matched == 5
            err[name].append((_ate(res, ds), lm.rmse))
    base = np.mean(err["ekf"], axis=0)
    assert base[0] < 0.06 and base[1] < 0.02  # measured 0.041, 0.012
    ratio1 = np.mean(err["1"], axis=0) / base
    ratio2 = np.mean(err["2"], axis=0) / base
    assert ratio1[0] < 1.5 and ratio1[1] < 1.5, ratio1  # measured 1.31, 1.21
    assert ratio2[0] < 2.5 and ratio2[1] < 1.75, ratio2  # measured 2.11, 1.46


def test_misses_count_only_within_the_sensors_detection_range() -> None:
    """The measured detection range is the 90th percentile of the readings' ranges over
    ``√0.9``, capped at the sensor's: for landmarks spread evenly around a sensor that reads
    all within ``R`` it is ``R``; a sensor that seldom reads far landmarks gets a shorter
    one, and a landmark predicted beyond it is not counted as missed."""
    from slamkit.datasets.stream import measured_detection_range

    rng = np.random.default_rng(0)
    r = 20.0 * np.sqrt(rng.uniform(0.0, 1.0, 20_000))  # uniform in a 20 m disc
    z = np.column_stack([r, rng.uniform(-np.pi, np.pi, r.size)])
    events = tuple(LandmarkReadings(float(i), z[i * 100 : (i + 1) * 100], np.full(100, -1))
                   for i in range(200))  # fmt: skip
    far, near = (
        LandmarkSensorSpec("range-bearing", R, 80.0),
        LandmarkSensorSpec("range-bearing", R, 15.0),
    )
    assert measured_detection_range(events, far) == pytest.approx(20.0, rel=0.02)
    assert measured_detection_range(events, near) == 15.0
    assert far.reach == 80.0 and replace(far, detection_range=20.0).reach == 20.0
    # A landmark at 30 m with a miss range of 20 m: not missed; at 10 m: missed.
    s = UpdateSettings(p0=1e-3, visible_max_range=20.0, first_unlabelled_id=0)
    ps = FastSlamParticles(np.zeros((1, 3)), np.zeros(1), np.array([[[30.0, 0.0], [10.0, 0.0]]]),
                           np.broadcast_to(0.01 * np.eye(2), (1, 2, 2, 2)).copy(),
                           np.array([[1, 0]]), np.array([[0, 1]]), np.array([2]),
                           2)  # fmt: skip
    far = RangeBearing().predict(np.zeros(3), [0.0, 50.0])[None]  # a new landmark elsewhere
    out, _ = fastslam1_update(ps, far, None, RangeBearing(), R, s)
    assert out.ids[0, :2].tolist() == [0, 2] and out.counters[0, 0] == 1  # 1 (10 m) removed


def test_visibility_is_judged_from_the_sensor_not_the_robot_origin() -> None:
    """Victoria Park's geometry: a 180° laser 3.78 m ahead of and 0.5 m left of the rear
    axle (the pose's origin), effective range 40 m. A tree beside the cab and one 30 m to
    the right level with the cab (ahead of the axle, behind the laser) are not in view, one
    42 m ahead of the axle is (38 m from the laser); judged from the axle it is the other
    way round. The same with the robot turned
    and moved (the test runs in the sensor frame of each particle)."""
    from slamkit.slam.fastslam.association import predicted_visible

    robot_frame = np.array([[2.0, 6.0], [10.0, 0.0], [42.0, 0.0], [3.0, -30.0], [-1.0, 0.0]])
    laser = UpdateSettings(p0=1e-3, visible_max_range=40.0, fov=np.pi, sensor_offset=(3.78, 0.5))
    axle = dataclasses.replace(laser, sensor_offset=(0.0, 0.0))
    for pose in (np.zeros(3), np.array([5.0, -3.0, 2.5])):
        world = RelativePosition().inverse(pose, robot_frame)  # (5, 2)
        poses = pose[None]
        x, y = world[:, :1], world[:, 1:]  # (C, P) with one particle
        assert predicted_visible(x, y, poses, laser)[:, 0].tolist() == [
            False, True, True, False, False]  # fmt: skip
        assert predicted_visible(x, y, poses, axle)[:, 0].tolist() == [
            True, True, False, True, False]  # fmt: skip
    with pytest.raises(ConfigError):
        UpdateSettings(p0=1e-3, sensor_offset=(np.nan, 0.0))


def test_the_sensor_offset_comes_from_the_data_set_or_the_config() -> None:
    """The landmark sensor's specification says where it sits (Victoria Park: the laser,
    ahead of the axle); by default at the robot's origin; the config overrides it."""
    from slamkit.slam.fastslam.config import sensor_offset_of

    ds = load_dataset("five-features", seed=0)
    assert ds.landmark_sensor is not None and sensor_offset_of(ds) == (0.0, 0.0)
    rng = np.random.default_rng(0)
    assert FastSlam1(ds, FastSlamConfig(n_particles=5), rng).settings.sensor_offset == (0.0, 0.0)
    sensor = dataclasses.replace(ds.landmark_sensor, offset=(1.5, -0.2))
    moved = dataclasses.replace(ds, landmark_sensor=sensor)
    assert sensor_offset_of(moved) == (1.5, -0.2)
    est = FastSlam1(moved, FastSlamConfig(n_particles=5), rng)
    assert est.settings.sensor_offset == (1.5, -0.2)
    cfg = FastSlamConfig(n_particles=5, sensor_offset=(0.0, 0.0))
    assert FastSlam1(moved, cfg, rng).settings.sensor_offset == (0.0, 0.0)
    for bad in ("front", (1.0, float("nan"))):
        with pytest.raises(InputError, match="offset"):
            dataclasses.replace(ds.landmark_sensor, offset=bad)
    with pytest.raises(ConfigError):
        FastSlamConfig(sensor_offset=(1.0, 2.0, 3.0))  # type: ignore[arg-type]


def test_sampled_ackermann_steering_stays_in_the_models_domain() -> None:
    """Steering noise of 1 rad per control: draws beyond the model's domain (|α| < π/2, the
    encoder wheel off the centre of rotation) saturate instead of stopping the run."""
    model = Ackermann(2.83, (0.0, 0.0), 0.76)
    events = tuple(Control(0.1 * (k + 1), np.array([2.0, 0.0]), 0.1) for k in range(50))
    ds = Dataset("steer", events, motion=MotionSpec(model, np.diag([0.1, 1.0])),
                 landmark_sensor=LandmarkSensorSpec("range-bearing", R),
                 initial_pose=np.zeros(3), initial_cov=np.zeros((3, 3)))  # fmt: skip
    with pytest.raises(GeometryError):  # the model itself refuses such a control
        model.apply(np.zeros((1, 3)), np.array([[2.0, 1.4]]), 0.1)
    for cls in (FastSlam1, FastSlam2):
        est = cls(ds, FastSlamConfig(n_particles=200), np.random.default_rng(0))
        for ev in ds.events:
            est.handle(ev)
        assert np.all(np.isfinite(est.particles.poses))


@pytest.mark.parametrize("version", [1, 2])
def test_animation_frames_show_the_best_map_and_the_particles(version: int) -> None:
    """``frames``: each frame holds the particle poses and the map of the heaviest particle;
    the last frame's map is the final map, and the cloud's centre is near the estimate."""
    ds = load_dataset("five-features", seed=0)
    result = run(ENTRIES[version], ds, config={"n_particles": 50}, seed=1, frames=8)
    assert 8 <= len(result.frames) <= 10
    for f in result.frames:
        assert f.particles is not None and f.particles.shape == (50, 3)
        assert np.hypot(*(f.particles[:, :2].mean(axis=0) - f.pose[:2])) < 0.2
        assert f.landmarks is not None and f.landmarks.covariances.shape[1:] == (2, 2)
    last, final = result.frames[-1].landmarks, result.output.landmarks
    assert last is not None and final is not None
    np.testing.assert_array_equal(last.landmarks.positions, final.landmarks.positions)
    np.testing.assert_array_equal(last.landmarks.ids, final.landmarks.ids)
