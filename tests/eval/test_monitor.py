"""The consistency monitor (slamkit.eval.monitor): the statistics on seeded draws with known
answers, and on filter runs — σ = 1e-6 readings make EKF localization over-confident by a
factor of about 10⁶, the nominal noise leaves it consistent."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets import load_dataset
from slamkit.errors import InputError, ShapeError
from slamkit.eval import (
    MONITOR_MARGIN,
    MONITOR_PROBABILITY,
    MONITOR_WINDOW,
    autocorrelation_time,
    chi2_bounds,
    nees_warning,
    nis_warning,
)
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate

W = MONITOR_WINDOW


def test_autocorrelation_time_of_white_and_ar1_sequences() -> None:
    rng = np.random.default_rng(0)
    assert autocorrelation_time(rng.normal(size=20_000)) == pytest.approx(1.0, abs=0.1)
    # AR(1) x_k = φ x_{k-1} + w_k: ρ_j = φ^j, τ = 1 + 2 φ / (1 − φ) = (1 + φ) / (1 − φ) = 9
    phi, x = 0.8, np.zeros(50_000)
    w = rng.normal(size=x.size)
    for k in range(1, x.size):
        x[k] = phi * x[k - 1] + w[k]
    assert autocorrelation_time(x) == pytest.approx(9.0, rel=0.15)
    assert autocorrelation_time(np.ones(10)) == 1.0


@pytest.mark.parametrize("seed", range(5))
def test_chi_square_draws_raise_no_warning(seed: int) -> None:
    rng = np.random.default_rng(seed)
    t = 0.1 * np.arange(2000)
    assert nees_warning(t, rng.chisquare(3, t.size), 3) is None
    dof = rng.integers(1, 3, t.size)  # one- and two-component readings mixed
    assert nis_warning(t, rng.chisquare(dof), dof) is None


def test_an_over_confident_stretch_is_reported_with_its_first_window_and_band() -> None:
    rng = np.random.default_rng(1)
    t = 0.1 * np.arange(1000)
    nis = rng.chisquare(2, t.size)
    nis[600:] *= 4.0  # the covariance four times too small from update 600 on
    dof = np.full(t.size, 2)
    w = nis_warning(t, nis, dof)
    assert w is not None and w.statistic == "nis" and w.direction == "over-confident"
    # the band of W updates of 2 dof, each window held to 1 − (1 − p) / (K / W)
    lo, hi = chi2_bounds(1, 2 * W, 1.0 - (1.0 - MONITOR_PROBABILITY) / (t.size / W))
    assert w.band == pytest.approx((lo, hi))
    assert w.value > hi * MONITOR_MARGIN
    assert w.last == w.first + W - 1 and w.start_time == pytest.approx(t[w.first])
    # the first window that far out overlaps the stretch by the part that lifts its mean
    assert 560 < w.first < 600
    assert w.value == pytest.approx(nis[w.first : w.first + W].sum() / (2 * W))
    assert "over-confident" in w.message and f"updates {w.first}-{w.last}" in w.message


def test_too_cautious_nees_and_bad_input() -> None:
    rng = np.random.default_rng(2)
    t = np.arange(500.0)
    w = nees_warning(t, 0.05 * rng.chisquare(3, t.size), 3)
    assert w is not None and w.direction == "too cautious" and w.first == 0
    assert w.value < w.band[0] / MONITOR_MARGIN
    assert nees_warning(t[: W - 1], np.full(W - 1, 1e9), 3) is None  # shorter than a window
    with pytest.raises(InputError, match="window"):
        nees_warning(t, np.ones(t.size), 3, window=1)
    with pytest.raises(InputError, match="non-negative"):
        nees_warning(t, -np.ones(t.size), 3)
    with pytest.raises(ShapeError, match="dof"):
        nis_warning(t, np.ones(t.size), np.zeros(t.size, dtype=int))
    with pytest.raises(InputError, match="margin"):
        nis_warning(t, np.ones(t.size), np.ones(t.size, dtype=int), margin=0.5)


def test_near_zero_sensor_noise_makes_ekf_localization_warn_in_its_scores() -> None:
    data = load_dataset(
        "five-features", seed=0, options={"sigma_range": 1e-6, "sigma_bearing_deg": 1e-6}
    )
    result = run("ekf-localization", data, seed=0)
    scores = evaluate(result, data).scores
    nees = [w for w in scores.warnings if w.statistic == "nees"]
    assert len(nees) == 1
    w = nees[0]
    assert w.direction == "over-confident" and w.first == 0
    assert w.value > 1e5 * w.band[1]  # measured: 7.2e6 against an upper end of 4.8
    assert w.windows_outside == w.windows  # every window of the run
    listed = scores.as_dict()["warnings"]
    assert listed[0]["statistic"] == "nees" and listed[0]["value"] == w.value


@pytest.mark.parametrize("seed", range(5))
def test_nominal_noise_raises_no_warning(seed: int) -> None:
    data = load_dataset("five-features", seed=seed)
    result = run("ekf-localization", data, seed=seed)
    scores = evaluate(result, data).scores
    assert scores.nees is not None and scores.nis is not None  # both statistics were tested
    assert scores.warnings == ()
    assert scores.as_dict()["warnings"] == []
