"""Where one EKF / UKF localization step's time goes: the general steps, their parts, and
the closed-form steps, in µs of CPU time per call (``time.process_time``, best of 7 × 5,000
calls: a loaded machine inflates it far less than wall time), on the data of
``bench_filters.py``; then whole estimator steps (best of 7 runs of 300 steps)::

    PYTHONPATH=src python benchmarks/profile_filters.py

The profile in ``docs/estimators/localization.md`` ("Speed") came from it.
"""

from __future__ import annotations

import functools
import os
import time
import timeit
from typing import Any

import numpy as np

import bench_filters as bench
from slamkit.estimation.gaussian import (
    check_covariance,
    gain_update,
    innovation_unchecked,
    measure_unchecked,
    predict_measurement_unchecked,
    solve_innovation,
)
from slamkit.localization.ukf import circular_mean_about, psd_sqrt, sigma_point_weights
from slamkit.models import RangeBearing, UnicycleEuler


def main() -> None:
    objs = bench.step_objects()
    rb, euler = RangeBearing(), UnicycleEuler()
    m = np.array([1.0, 2.0, 0.3])
    P = np.array([[0.01, 0.001, 0.0], [0.001, 0.02, 0.0], [0.0, 0.0, 0.003]])
    u, z, lm = np.array([1.0, 0.2]), np.array([5.0, 0.4]), bench.LANDMARKS[0]
    H = measure_unchecked(rb, m, lm)[1]
    nu = np.array([0.01, 0.002])
    Wm = sigma_point_weights(bench.PARAMS, 3)[0]
    X = m + np.zeros((7, 3))
    X[1:4] += 0.1
    S, rhs = np.eye(2), np.ones((2, 4))
    R = bench.R_RB
    names: dict[str, Any] = dict(locals(), np=np, check_covariance=check_covariance,
                                 gain_update=gain_update, innovation=innovation_unchecked,
                                 measure=measure_unchecked, psd_sqrt=psd_sqrt,
                                 predict_many=predict_measurement_unchecked,
                                 circular_mean_about=circular_mean_about,
                                 solve_innovation=solve_innovation)  # fmt: skip
    rows = [
        ("EKF general predict", "objs['ekf_general'].predict(m, P, u, 0.1)"),
        ("  motion model: step_single (g, G, V)", "euler.step_single(m, u, 0.1)"),
        ("  check_covariance (3 x 3)", "check_covariance(P, 'x')"),
        ("EKF general update", "objs['ekf_general'].update(m, P, z, lm)"),
        ("  landmark model: predict_with_pose_jacobian", "measure(rb, m, lm)"),
        ("  innovation (bearing wrapped)", "innovation(rb, z, z, (1,))"),
        ("  gain_update (gain, Joseph form, check)", "gain_update(m, P, nu, H, R)"),
        ("EKF closed-form predict", "objs['ekf_closed'].predict(m, P, u, 0.1)"),
        ("EKF closed-form update", "objs['ekf_closed'].update(m, P, z, lm)"),
        ("UKF general predict (11 augmented points)", "objs['ukf_general'].predict(m, P, u, 0.1)"),
        ("UKF general update (7 points)", "objs['ukf_general'].update(m, P, z, lm)"),
        ("  psd_sqrt (Cholesky)", "psd_sqrt(P, 'x')"),
        ("  landmark model on 7 points", "predict_many(rb, X, lm)"),
        ("  circular_mean_about (7 angles)", "circular_mean_about(X[:, 2], Wm, 0.3)"),
        ("  solve_innovation (2 x 2, 4 columns)", "solve_innovation(S, rhs, 'x')"),
        ("UKF closed-form predict", "objs['ukf_closed'].predict(m, P, u, 0.1)"),
        ("UKF closed-form update", "objs['ukf_closed'].update(m, P, z, lm)"),
    ]  # fmt: skip
    print(f"load average {os.getloadavg()[0]:.1f}")
    for name, stmt in rows:
        timer = timeit.Timer(stmt, timer=time.process_time, globals=names)
        best = min(timer.repeat(number=5000, repeat=7)) / 5000
        print(f"{name:48s} {best * 1e6:7.1f} µs")
    ds = bench.make_dataset(300)
    for which in ("ekf", "ukf"):
        step = functools.partial(bench.slamkit_estimator, ds, which)
        timer = timeit.Timer(step, timer=time.process_time)
        runs = timer.repeat(number=1, repeat=7)
        print(f"{which.upper()} estimator step (predict + 3 updates + events)"
              f" {min(runs) / 300 * 1e6:7.1f} µs")  # fmt: skip
    print(f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
