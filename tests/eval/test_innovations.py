"""NIS summaries: consistent innovations pass, over-confident ones fail."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.errors import InputError, ShapeError
from slamkit.eval import nis_summary


def test_consistent_chi2_draws_are_consistent_and_scaled_ones_are_not():
    rng = np.random.default_rng(0)
    dof = rng.choice([1, 2], size=5000)
    nis = rng.chisquare(dof)
    t = np.sort(rng.uniform(0, 1000, 5000))
    ok = nis_summary(t, nis, dof, window=50)
    assert ok.mean_per_dof == pytest.approx(1.0, abs=0.05)
    assert ok.fraction_in_band == pytest.approx(0.95, abs=0.015)
    # 100 windows, each inside its 95 % band with probability 0.95.
    assert ok.fraction_windows_consistent > 0.88
    assert ok.consistent_time_fraction > 0.85
    # A filter whose innovations are twice as large as it claims (NIS × 4).
    bad = nis_summary(t, 4 * nis, dof, window=50)
    assert bad.mean_per_dof == pytest.approx(4.0, rel=0.05)
    assert bad.fraction_windows_consistent < 0.02
    assert set(ok.as_dict()) >= {"mean_nis_per_dof", "consistent_time_fraction"}


def test_hand_case_and_errors():
    s = nis_summary([0.0, 1.0, 2.0], [1.0, 1.0, 1.0], np.array([1, 1, 1]), window=2)
    assert s.window_sums.tolist() == [2.0, 1.0] and s.mean_per_dof == 1.0
    with pytest.raises(ShapeError):
        nis_summary([0.0], [1.0], np.array([0]))
    with pytest.raises(InputError):
        nis_summary([0.0], [-1.0], np.array([1]))
