"""TUM trajectory files: stamps and poses survive a write and a read."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slamkit.io.tum import read_tum, write_tum


def test_unix_stamps_keep_their_microseconds(tmp_path: Path) -> None:
    times = np.array([976052896.784509, 976052905.167303, 976052911.885496])
    poses = np.array([[1.0, -2.0, 0.3], [1.5, -2.5, -3.1], [0.0, 0.0, 0.0]])
    write_tum(tmp_path / "t.tum", times, poses)
    t, p = read_tum(tmp_path / "t.tum")
    np.testing.assert_allclose(t, times, rtol=0, atol=1e-6)
    np.testing.assert_allclose(p, poses, atol=1e-8)
