"""The pose-landmark fixed-lag smoother: equal to batch when the window holds the whole run; a
short window's error against batch bounded by a measured number; the pose-landmark marginal
prior equal to the dense Schur complement of the removed factors on a tiny graph; Victoria
Park's iSAM file (real data, skipped when absent); bad input refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slamkit.errors import InputError
from slamkit.geometry import pose2
from slamkit.geometry.angles import wrap_angle
from slamkit.optim import EdgeSet, GraphData, OptimizerConfig, StoppingConfig, factors, optimize
from slamkit.optim.fixed_lag import FixedLagConfig
from slamkit.optim.fixed_lag_landmarks import (
    LandmarkFixedLagSmoother,
    landmark_updates,
    smooth_landmark_fixed_lag,
)

ODO_INFO = np.diag([400.0, 400.0, 2500.0])  # σ = 5 cm, 5 cm, 0.02 rad
RB_INFO = np.diag([1 / 0.1**2, 1 / 0.01**2])  # σ = 0.1 m, 0.01 rad
TIGHT = OptimizerConfig(
    solver="gn",
    initialization="vertices",
    stopping=StoppingConfig(relative_tolerance=0.0, absolute_tolerance=0.0, max_iterations=50),
)


def _landmark_graph(rng: np.random.Generator, poses: int, laps: float = 1.0) -> GraphData:
    """A robot on a circle of radius 10 m among 12 landmarks, odometry and range-bearing
    readings (range ≤ 8 m) with the noise of ``ODO_INFO`` / ``RB_INFO``; vertices at dead
    reckoning, landmarks at their first reading."""
    a = np.linspace(0.0, 2 * np.pi * laps, poses)
    truth = np.stack([10 * np.cos(a), 10 * np.sin(a), wrap_angle(a + np.pi / 2)], axis=1)
    b = np.linspace(0.0, 2 * np.pi, 12, endpoint=False)
    rad = np.where(np.arange(12) % 2 == 0, 7.0, 13.0)
    lms = np.stack([rad * np.cos(b), rad * np.sin(b)], axis=1)
    rel = np.array([pose2.between(truth[k], truth[k + 1]) for k in range(poses - 1)])
    rel += rng.normal(size=rel.shape) * np.sqrt(1 / np.diag(ODO_INFO))
    pi, lj, zs = [], [], []
    for k in range(poses):
        q = pose2.inverse_transform_points(truth[k], lms)
        r = np.hypot(q[:, 0], q[:, 1])
        for m in np.flatnonzero(r <= 8.0):
            z = np.array([r[m], np.arctan2(q[m, 1], q[m, 0])])
            pi.append(k)
            lj.append(m)
            zs.append(z + rng.normal(size=2) * np.array([0.1, 0.01]))
    n = len(pi)
    dead = [truth[0]]
    for z in rel:
        dead.append(pose2.compose(dead[-1], z))
    X0 = np.array(dead)
    first: dict[int, np.ndarray] = {}
    for k, m, z in zip(pi, lj, zs, strict=True):
        if m not in first:
            x = X0[k]
            first[m] = x[:2] + z[0] * np.array([np.cos(x[2] + z[1]), np.sin(x[2] + z[1])])
    ids = np.array(sorted(first), dtype=np.int64)
    return GraphData(
        dim=2,
        pose_ids=np.arange(poses, dtype=np.int64),
        poses=X0,
        landmark_ids=ids,
        landmarks=np.array([first[int(m)] for m in ids]),
        edges=(
            EdgeSet(
                "se2",
                np.arange(poses - 1),
                np.arange(1, poses),
                rel,
                np.broadcast_to(ODO_INFO, (poses - 1, 3, 3)).copy(),
                np.zeros(poses - 1, dtype=np.int64),
            ),
            EdgeSet(
                "range_bearing",
                np.array(pi),
                np.array(lj),
                np.array(zs),
                np.broadcast_to(RB_INFO, (n, 2, 2)).copy(),
                np.zeros(n, dtype=np.int64),
            ),
        ),
        fixed_ids=np.array([0], dtype=np.int64),
    )


def _batch(g: GraphData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    res = optimize(g, TIGHT)
    return res.poses, res.landmark_ids, res.landmarks


def test_window_covering_the_run_equals_batch() -> None:
    g = _landmark_graph(np.random.default_rng(1), 40)
    res = smooth_landmark_fixed_lag(g, FixedLagConfig(window=40))
    X, lid, P = _batch(g)
    assert res.converged and res.reentries == 0 and res.dropped_edges == 0
    np.testing.assert_array_equal(res.landmark_ids, lid)
    np.testing.assert_allclose(res.poses, X, atol=1e-8)
    np.testing.assert_allclose(res.landmarks, P, atol=1e-8)


def test_short_window_stays_near_batch() -> None:
    """Window 8 (48° of arc) over 1.5 laps, seeds 0-4: the online estimates against batch,
    which closes the loop the window cannot (the landmarks seen again re-enter as new
    variables). Measured: worst max 1.19 m, worst translation RMSE 0.54 m (seed 3); the
    bounds leave ~20 % margin. The step's system never exceeds 34 unknowns (measured) of the
    bound 3·9 + 2·12 (nine poses before the oldest leaves, every landmark)."""
    worst_max, worst_rmse = 0.0, 0.0
    for seed in range(5):
        g = _landmark_graph(np.random.default_rng(seed), 90, laps=1.5)
        res = smooth_landmark_fixed_lag(g, FixedLagConfig(window=8))
        X, _, _ = _batch(g)
        d = np.hypot(*(res.poses[:, :2] - X[:, :2]).T)
        worst_max = max(worst_max, float(d.max()))
        worst_rmse = max(worst_rmse, float(np.sqrt(np.mean(d**2))))
        assert res.max_unknowns <= 3 * 9 + 2 * 12
        assert res.reentries > 0  # the second half-lap sees the first lap's landmarks again
    assert worst_max < 1.4
    assert worst_rmse < 0.65


def _dense_information(
    g: GraphData, X: np.ndarray, P: np.ndarray, lm_ids: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``H = JᵀJ``, ``g = Jᵀr`` of every factor of ``g`` over all poses but the anchor
    (3 columns each) then all landmarks (2 each), Jacobians by central differences."""
    n, m = X.shape[0] - 1, P.shape[0]

    def residual(v: np.ndarray) -> np.ndarray:
        Xv = np.vstack([X[:1], factors.retract_poses(X[1:], v[: 3 * n].reshape(n, 3))])
        Pv = P + v[3 * n :].reshape(m, 2)
        out = []
        for es in g.edges:
            U = np.swapaxes(np.linalg.cholesky(es.information), 1, 2)
            if es.kind == "se2":
                e, _, _ = factors.se2_between_error(Xv[es.i], Xv[es.j], es.measurement)
            else:
                rows = np.searchsorted(lm_ids, es.j)
                e, _, _ = factors.range_bearing_error(Xv[es.i], Pv[rows], es.measurement)
            out.append(np.einsum("eij,ej->ei", U, e).ravel())
        return np.concatenate(out)

    size = 3 * n + 2 * m
    r0 = residual(np.zeros(size))
    J = np.zeros((r0.shape[0], size))
    h = 1e-6
    for k in range(size):
        dv = np.zeros(size)
        dv[k] = h
        J[:, k] = (residual(dv) - residual(-dv)) / (2 * h)
    return J.T @ J, J.T @ r0


def test_marginal_prior_equals_dense_schur_complement() -> None:
    """Four poses, window 2: after pose 3 the prior is what poses 1 (and the landmarks only it
    saw) leave on pose 2 and the landmarks pose 2 or 3 still see — equal to the Schur
    complement of the dense information of every factor touching them, formed by finite
    differences at the estimate the smoother marginalised at."""
    g = _landmark_graph(np.random.default_rng(3), 4, laps=0.25)
    sm = LandmarkFixedLagSmoother(FixedLagConfig(window=2, max_iterations=1))
    steps = landmark_updates(g)
    for pid, edges in steps[:3]:
        sm.update(pid, edges)
    _, _, lm_file, _ = sm.window_estimate()  # the landmarks of poses 1, 2
    sm.update(*steps[3])
    prior = sm.prior()
    assert prior is not None
    # the graph of poses 0-2 and the landmarks they see, at the estimate before the step
    # (pose 3's factors do not touch pose 1 or the landmarks leaving with it)
    keep = [es for es in g.edges]
    se2, rb = keep
    s_rows = np.flatnonzero(se2.j <= 2)
    o_rows = np.flatnonzero(rb.i <= 2)
    sub = GraphData(
        dim=2,
        pose_ids=np.arange(3, dtype=np.int64),
        poses=np.zeros((3, 3)),
        edges=(
            EdgeSet(
                "se2",
                se2.i[s_rows],
                se2.j[s_rows],
                se2.measurement[s_rows],
                se2.information[s_rows],
                se2.lines[s_rows],
            ),
            EdgeSet(
                "range_bearing",
                rb.i[o_rows],
                rb.j[o_rows],
                rb.measurement[o_rows],
                rb.information[o_rows],
                rb.lines[o_rows],
            ),
        ),
    )
    # factors touching pose 1 or a landmark seen by pose 1 and not by poses 2, 3
    seen_later = set(rb.j[rb.i >= 2].tolist())
    gone = sorted(set(rb.j[rb.i == 1].tolist()) - seen_later)
    touch_s = (sub.edges[0].i == 1) | (sub.edges[0].j == 1)
    e1 = sub.edges[1]
    touch_o = (e1.i == 1) | np.isin(e1.j, gone)
    touched = GraphData(
        dim=2,
        pose_ids=sub.pose_ids,
        poses=sub.poses,
        edges=(
            EdgeSet(
                "se2",
                *(
                    a[touch_s]
                    for a in (
                        sub.edges[0].i,
                        sub.edges[0].j,
                        sub.edges[0].measurement,
                        sub.edges[0].information,
                        sub.edges[0].lines,
                    )
                ),
            ),
            EdgeSet(
                "range_bearing",
                *(a[touch_o] for a in (e1.i, e1.j, e1.measurement, e1.information, e1.lines)),
            ),
        ),
    )
    # the estimate marginalised at: pose 1 and the landmarks leaving with it at their online
    # estimates, the separator at the prior's linearisation point
    res = sm.finish()
    lm_sorted = np.sort(lm_file)
    P = np.array([
        prior.point_point[list(prior.point_ids).index(q)] if q in prior.point_ids
        else res.landmarks[list(res.landmark_ids).index(q)]
        for q in lm_sorted.tolist()
    ])  # fmt: skip
    X = np.vstack([np.zeros(3), res.poses[1], prior.pose_point[0]])  # poses 0, 1, 2
    H, gv = _dense_information(touched, X, P, lm_sorted)
    # unknowns: poses 1, 2 (cols 0-5), then landmarks in sorted file order
    col = {int(q): 6 + 2 * k for k, q in enumerate(lm_sorted.tolist())}
    elim = [0, 1, 2] + [c + t for q in gone for c in [col[q]] for t in (0, 1)]
    sep = [3, 4, 5] + [col[int(q)] + t for q in prior.point_ids for t in (0, 1)]
    Hmm = H[np.ix_(elim, elim)]
    Hms = H[np.ix_(elim, sep)]
    schur = H[np.ix_(sep, sep)] - Hms.T @ np.linalg.solve(Hmm, Hms)
    gs = gv[sep] - Hms.T @ np.linalg.solve(Hmm, gv[elim])
    np.testing.assert_array_equal(prior.pose_ids, [2])
    np.testing.assert_allclose(
        prior.R.T @ prior.R, schur, rtol=1e-5, atol=1e-6 * np.abs(schur).max()
    )
    np.testing.assert_allclose(
        prior.R.T @ prior.d, gs, rtol=1e-5, atol=1e-6 * np.abs(gs).max() + 1e-9
    )


def test_bad_input_is_refused() -> None:
    g = _landmark_graph(np.random.default_rng(0), 5)
    with pytest.raises(InputError, match="edge kinds bearing"):
        bad = EdgeSet("bearing", np.array([1]), np.array([0]), np.zeros((1, 1)),
                      np.ones((1, 1, 1)), np.zeros(1, dtype=np.int64))  # fmt: skip
        smooth_landmark_fixed_lag(GraphData(dim=2, pose_ids=g.pose_ids, poses=g.poses,
                                            edges=(*g.edges, bad)))  # fmt: skip
    sm = LandmarkFixedLagSmoother()
    sm.update(0, ())
    with pytest.raises(InputError, match="ids must increase"):
        sm.update(0, ())


VICTORIA = Path("isam/victoriaPark.txt")


def test_victoria_park_isam_file(data_root: Path) -> None:
    path = data_root / VICTORIA
    if not path.exists():
        pytest.skip(f"{VICTORIA} not under the data root")
    from slamkit.io.posegraph import read_graph

    g = read_graph(path)
    res = smooth_landmark_fixed_lag(g, FixedLagConfig(window=20))
    assert res.steps == 6969 and res.landmark_ids.shape[0] == 151
