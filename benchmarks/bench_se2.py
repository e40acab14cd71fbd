"""Batched SE(2) composition: slamkit's vectorised kernels against a per-pose Python loop.

The same 10⁶ pairs of poses ``(x, y, θ)`` are composed three ways by slamkit —
``pose2.compose`` on ``(N, 3)`` arrays, ``SE2 @ SE2`` on group values built beforehand, and the
full ``SE2.from_xy_theta`` → ``@`` → ``xy_theta()`` round trip — and once by a straightforward
Python loop (``math.cos``/``math.sin`` per pose over lists of tuples, the inputs converted to
lists before timing). All answers are checked against each other before anything is written.

Run: ``python benchmarks/bench_se2.py`` or ``python benchmarks/run.py se2``.
"""

from __future__ import annotations

import math

import numpy as np

from _common import Record, best_of, write_results
from slamkit.geometry import pose2
from slamkit.geometry.angles import angle_diff
from slamkit.geometry.se2 import SE2

_TWO_PI = 2.0 * math.pi


def compose_loop(
    a: list[tuple[float, float, float]], b: list[tuple[float, float, float]]
) -> list[tuple[float, float, float]]:
    """The peer: ``a[i] ⊕ b[i]`` one pose at a time in plain Python."""
    out = []
    for (x1, y1, t1), (x2, y2, t2) in zip(a, b, strict=True):
        c, s = math.cos(t1), math.sin(t1)
        theta = (t1 + t2 + math.pi) % _TWO_PI - math.pi
        out.append((x1 + c * x2 - s * y2, y1 + s * x2 + c * y2, theta))
    return out


def _check_same(actual: np.ndarray, expected: np.ndarray, what: str) -> None:
    xy_error = float(np.max(np.abs(actual[:, :2] - expected[:, :2])))
    theta_error = float(np.max(np.abs(angle_diff(actual[:, 2], expected[:, 2]))))
    if max(xy_error, theta_error) > 1e-9:
        raise AssertionError(f"{what} disagrees with the loop: {xy_error:.3g}, {theta_error:.3g}")


def main(n: int = 1_000_000, repeats: int = 3, seed: int = 0) -> str:
    rng = np.random.default_rng(seed)
    a = np.column_stack([10.0 * rng.standard_normal((n, 2)), rng.uniform(-np.pi, np.pi, n)])
    b = np.column_stack([10.0 * rng.standard_normal((n, 2)), rng.uniform(-np.pi, np.pi, n)])
    a_list = [tuple(p) for p in a.tolist()]
    b_list = [tuple(p) for p in b.tolist()]
    A, B = SE2.from_xy_theta(a), SE2.from_xy_theta(b)

    t_loop, loop_out = best_of(lambda: compose_loop(a_list, b_list), repeats)
    t_arrays, arrays_out = best_of(lambda: pose2.compose(a, b), repeats)
    t_group, group_out = best_of(lambda: A @ B, repeats)
    t_round, round_out = best_of(
        lambda: (SE2.from_xy_theta(a) @ SE2.from_xy_theta(b)).xy_theta(), repeats
    )

    expected = np.asarray(loop_out)
    _check_same(arrays_out, expected, "pose2.compose")
    _check_same(group_out.xy_theta(), expected, "SE2 @ SE2")
    _check_same(round_out, expected, "SE2 round trip")

    peer = "Python loop (math.cos/sin per pose)"
    records = [
        Record(f"pose2.compose, {n:,} (N, 3) pose pairs", t_arrays, peer, t_loop),
        Record(f"SE2 @ SE2, batch of {n:,}", t_group, peer, t_loop),
        Record(f"SE2.from_xy_theta → @ → xy_theta(), {n:,}", t_round, peer, t_loop),
    ]
    notes = (
        f"Best of {repeats} runs each, same inputs (seed {seed}) in the same process. The loop "
        "reads and writes Python lists of tuples; converting the arrays to lists is not timed. "
        "`SE2 @ SE2` excludes building the group values; the round-trip row includes it. "
        "All outputs agree with the loop to 1e-9."
    )
    return write_results("se2", records, notes)


if __name__ == "__main__":
    print(main())
