"""``viz.gps_fusion.plot_gps_fusion`` draws exactly the data it is given on the given axes."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from slamkit.viz.gps_fusion import plot_gps_fusion
from slamkit.viz.plots import new_figure


def test_plot_gps_fusion_draws_path_map_and_fixes() -> None:
    ax = new_figure().add_subplot()
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.1], [2.0, 1.0, 0.2]])
    landmarks = np.array([[0.5, 2.0], [1.5, -1.0]])
    fixes = np.array([[0.1, 0.0], [1.0, 0.6], [2.1, 1.0], [3.0, 1.5]])
    held = np.array([False, True, False, False])
    plot_gps_fusion(ax, poses, landmarks, fixes, held, label="fused")
    np.testing.assert_allclose(ax.lines[0].get_xydata(), poses[:, :2])
    offsets = [c.get_offsets() for c in ax.collections]
    np.testing.assert_allclose(offsets[0], fixes[~held])
    np.testing.assert_allclose(offsets[1], fixes[held])
    np.testing.assert_allclose(offsets[2], landmarks)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "fused" in labels and "GPS (held out)" in labels


def test_plot_gps_fusion_without_fixes() -> None:
    ax = new_figure().add_subplot()
    plot_gps_fusion(ax, np.zeros((2, 3)), np.ones((1, 2)))
    assert len(ax.collections) == 1 and len(ax.lines) == 1
