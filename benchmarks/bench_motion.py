"""Batched motion propagation: slamkit's vectorised models against a per-pose Python loop.

10⁶ poses ``(x, y, θ)`` with 10⁶ controls ``(v, ω)`` are propagated one step by the unicycle
models (Euler and exact arc), by noisy sampling (what a particle filter does every step) and
by the Jacobians ``G, V`` (what an EKF over many hypotheses needs), each time by slamkit on
``(N, 3)`` arrays and by a straightforward Python loop over lists in the same run. Answers are
checked against each other before anything is written (sampling: same noise draws).

Run: ``python benchmarks/bench_motion.py`` or ``python benchmarks/run.py motion``.
"""

from __future__ import annotations

import math

import numpy as np

from _common import Record, best_of, write_results
from slamkit.geometry.angles import angle_diff
from slamkit.models import UnicycleArc, UnicycleEuler

DT = 0.1
_TWO_PI = 2.0 * math.pi


def _wrap(a: float) -> float:
    return (a + math.pi) % _TWO_PI - math.pi


def euler_loop(poses: list[tuple[float, float, float]], controls: list[tuple[float, float]]):
    out = []
    for (x, y, t), (v, w) in zip(poses, controls, strict=True):
        out.append((x + v * math.cos(t) * DT, y + v * math.sin(t) * DT, _wrap(t + w * DT)))
    return out


def arc_loop(poses: list[tuple[float, float, float]], controls: list[tuple[float, float]]):
    out = []
    for (x, y, t), (v, w) in zip(poses, controls, strict=True):
        if abs(w * DT) < 1e-9:
            out.append((x + v * math.cos(t) * DT, y + v * math.sin(t) * DT, _wrap(t)))
            continue
        r = v / w
        t2 = t + w * DT
        out.append((x + r * (math.sin(t2) - math.sin(t)), y - r * (math.cos(t2) - math.cos(t)),
                    _wrap(t2)))  # fmt: skip
    return out


def euler_jacobian_loop(poses, controls):
    out = []
    for (_, _, t), (v, _) in zip(poses, controls, strict=True):
        c, s = math.cos(t), math.sin(t)
        G = ((1.0, 0.0, -v * s * DT), (0.0, 1.0, v * c * DT), (0.0, 0.0, 1.0))
        V = ((c * DT, 0.0), (s * DT, 0.0), (0.0, DT))
        out.append((G, V))
    return out


def _check(actual: np.ndarray, expected: np.ndarray, what: str, tol: float = 1e-9) -> None:
    xy = float(np.max(np.abs(actual[:, :2] - expected[:, :2])))
    th = float(np.max(np.abs(angle_diff(actual[:, 2], expected[:, 2]))))
    if max(xy, th) > tol:
        raise AssertionError(f"{what}: slamkit and the loop disagree ({xy:.3g}, {th:.3g})")


def main(n: int = 1_000_000, repeats: int = 3, seed: int = 0) -> str:
    rng = np.random.default_rng(seed)
    poses = np.column_stack([rng.normal(0, 10, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    controls = np.column_stack([rng.uniform(0, 2, n), rng.uniform(-1, 1, n)])
    p_list = [tuple(p) for p in poses.tolist()]
    u_list = [tuple(u) for u in controls.tolist()]
    Q = np.diag([0.05**2, 0.02**2])
    euler, arc = UnicycleEuler(), UnicycleArc()

    records = []
    t_loop, loop_out = best_of(lambda: euler_loop(p_list, u_list), repeats)
    t_ours, ours = best_of(lambda: euler.apply(poses, controls, DT), repeats)
    _check(ours, np.asarray(loop_out), "Euler")
    records.append(Record(f"UnicycleEuler.apply, {n:,} poses", t_ours, "Python loop", t_loop))

    t_loop, loop_out = best_of(lambda: arc_loop(p_list, u_list), repeats)
    t_ours, ours = best_of(lambda: arc.apply(poses, controls, DT), repeats)
    _check(ours, np.asarray(loop_out), "arc", tol=1e-7)
    records.append(Record(f"UnicycleArc.apply, {n:,} poses", t_ours, "Python loop", t_loop))

    # Sampling: both sides use the same standard-normal draws, so the answers must agree.
    eps = rng.standard_normal((n, 2)) * np.sqrt(np.diag(Q))
    noisy = [(u[0] + e[0], u[1] + e[1]) for u, e in zip(u_list, eps.tolist(), strict=True)]

    def loop_sample():
        return euler_loop(
            p_list, [(u[0] + e[0], u[1] + e[1]) for u, e in zip(u_list, eps_l, strict=True)]
        )

    eps_l = eps.tolist()
    t_loop, loop_out = best_of(loop_sample, repeats)
    sample_rng = np.random.default_rng(1)
    t_ours, _ = best_of(lambda: euler.sample(poses, controls, DT, Q, sample_rng), repeats)
    _check(euler.apply(poses, controls + eps, DT), np.asarray(euler_loop(p_list, noisy)), "noisy")
    records.append(
        Record(f"UnicycleEuler.sample (particles), {n:,}", t_ours, "Python loop + noise", t_loop)
    )

    t_loop, loop_out = best_of(lambda: euler_jacobian_loop(p_list, u_list), repeats)
    t_ours, (G, V) = best_of(lambda: euler.jacobians(poses, controls, DT), repeats)
    G_loop = np.asarray([g for g, _ in loop_out[:1000]])
    V_loop = np.asarray([v for _, v in loop_out[:1000]])
    if not (np.allclose(G[:1000], G_loop, atol=1e-12) and np.allclose(V[:1000], V_loop)):
        raise AssertionError("Jacobians disagree")
    records.append(
        Record(f"UnicycleEuler.jacobians (G, V), {n:,}", t_ours, "Python loop (tuples)", t_loop)
    )
    notes = (
        f"Best of {repeats} runs, dt = {DT} s, same inputs (seed {seed}) in one process. The loop "
        "reads and writes Python lists of tuples; converting arrays to lists is not timed. "
        "slamkit's sample() draws its own noise (not compared); the same step with the loop's "
        "noise is checked against the loop. Answers agree to 1e-9 (arc form 1e-7)."
    )
    return write_results("motion", records, notes)


if __name__ == "__main__":
    print(main())
