"""Leave-out GPS scoring (:func:`slamkit.eval.gps_holdout.holdout_gps_error`) on hand-built
tracks: an estimate in another frame is aligned on the fixes it keeps and scored on the held
ones; the lever arm moves the scored point; bad input is refused."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.errors import InputError
from slamkit.eval.gps_holdout import holdout_gps_error
from slamkit.geometry import pose2


def _circle(n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """A drive around a 20 m circle at 2 m/s: times and poses (heading along the track)."""
    t = np.arange(n) * 0.5
    a = t * 2.0 / 20.0
    poses = np.stack([20 * np.cos(a), 20 * np.sin(a), a + np.pi / 2], axis=1)
    return t, poses


def test_aligned_and_direct_errors_by_hand() -> None:
    """The fixes are the antenna (lever arm (1, 0)) of the true poses, the estimate is the
    truth moved by a rigid motion, and every held-out fix is 0.5 m off: the aligned error is
    0.5 m at each held fix (the alignment is fitted on the exact ones), the direct error is
    the rigid motion's displacement."""
    t, poses = _circle()
    lever = np.array([1.0, 0.0])
    fixes = pose2.transform_points(poses, lever[None, :].repeat(len(t), 0))
    held = np.arange(len(t)) % 10 == 9
    fixes[held, 1] += 0.5
    moved = pose2.compose(np.array([3.0, -2.0, 0.4]), poses)
    h = holdout_gps_error(t, moved, t, fixes, held, lever_arm=lever)
    assert h.scored.sum() == held.sum() == 20 and h.fitted == 180
    np.testing.assert_allclose(h.aligned_errors, 0.5, atol=1e-9)
    assert h.rmse == pytest.approx(0.5) and h.median == pytest.approx(0.5)
    assert h.alignment.angle == pytest.approx(-0.4, abs=1e-9)
    assert h.direct_rmse > 5.0


def test_fixes_between_samples_are_interpolated() -> None:
    t, poses = _circle()
    fix_t = t[:-1] + 0.25  # every fix halfway between two estimate samples
    mid = pose2.interpolate_poses(t, poses, fix_t)
    held = np.arange(fix_t.size) % 10 == 0
    h = holdout_gps_error(t, poses, fix_t, mid[:, :2], held)
    np.testing.assert_allclose(h.direct_errors, 0.0, atol=1e-9)


def test_bad_input_is_refused() -> None:
    t, poses = _circle(20)
    with pytest.raises(InputError, match="held_out"):
        holdout_gps_error(t, poses, t, poses[:, :2], np.ones(3, dtype=bool))
    with pytest.raises(InputError, match="to score"):
        holdout_gps_error(t, poses, t, poses[:, :2], np.zeros(20, dtype=bool))
