"""slamkit.viz: every plot function runs headless and draws what it was given."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.quiver import Quiver

from slamkit.errors import CovarianceError, InputError, ShapeError
from slamkit.maps import LandmarkMap, OccupancyGrid, SegmentMap
from slamkit.prob import chi2_gate
from slamkit.viz import (
    new_figure,
    plot_consistency,
    plot_covariance_ellipses,
    plot_landmark_estimates,
    plot_landmarks,
    plot_occupancy_grid,
    plot_pose_errors,
    plot_segments,
    plot_trajectories,
    plot_trajectory,
    save_figure,
)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def circle_poses(n: int = 50, radius: float = 5.0) -> np.ndarray:
    t = np.linspace(0.0, 2.0 * np.pi, n)
    return np.stack([radius * np.cos(t), radius * np.sin(t), t + np.pi / 2], axis=-1)


def polygon_vertices(coll: PolyCollection) -> list[np.ndarray]:
    """The vertices of each polygon without the closing point that matplotlib appends."""
    return [p.vertices[:-1] for p in coll.get_paths()]


@pytest.fixture
def fig() -> Figure:
    return new_figure(figsize=(4.0, 3.0), dpi=50)


def test_new_figure_is_headless_and_leaves_pyplot_alone() -> None:
    code = (
        "import sys\n"
        "from slamkit.viz import new_figure\n"
        "fig = new_figure()\n"
        "fig.add_subplot().plot([0, 1], [0, 1])\n"
        "fig.canvas.draw()\n"
        "sys.exit(int('matplotlib.pyplot' in sys.modules) + 2 * int(type(fig.canvas).__name__ "
        "!= 'FigureCanvasAgg'))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True)
    assert result.returncode == 0, result.stderr.decode()


def test_plot_trajectory_draws_the_input(fig: Figure) -> None:
    ax = fig.add_subplot()
    poses = circle_poses()
    artists = plot_trajectory(ax, poses, label="run", color="red")
    assert len(artists) == 1
    np.testing.assert_array_equal(artists[0].get_xydata(), poses[:, :2])
    assert artists[0].get_label() == "run"


def test_plot_trajectory_heading_arrows(fig: Figure) -> None:
    ax = fig.add_subplot()
    poses = circle_poses(n=50, radius=5.0)
    _line, quiver = plot_trajectory(ax, poses, heading_every=10, heading_length=0.5)
    assert isinstance(quiver, Quiver)
    np.testing.assert_allclose(quiver.X, poses[::10, 0])
    np.testing.assert_allclose(quiver.Y, poses[::10, 1])
    np.testing.assert_allclose(np.hypot(quiver.U, quiver.V), 0.5)
    np.testing.assert_allclose(np.arctan2(quiver.V, quiver.U), np.arctan2(
        np.sin(poses[::10, 2]), np.cos(poses[::10, 2])), atol=1e-12)  # fmt: skip
    with pytest.raises(InputError):
        plot_trajectory(ax, poses, heading_every=-1)


def test_plot_trajectories_styles_and_aspect(fig: Figure) -> None:
    ax = fig.add_subplot()
    truth = circle_poses()
    drawn = plot_trajectories(ax, truth=truth, estimate=truth + 0.1, dead_reckoning=truth * 1.2)
    assert set(drawn) == {"truth", "estimate", "dead_reckoning"}
    assert drawn["truth"][0].get_color() == "black"
    assert drawn["estimate"][0].get_color() == "tab:blue"
    assert drawn["dead_reckoning"][0].get_linestyle() == "--"
    np.testing.assert_allclose(drawn["estimate"][0].get_xydata(), truth[:, :2] + 0.1)
    assert ax.get_aspect() == 1.0
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["dead reckoning", "ground truth", "estimate"]
    only = plot_trajectories(new_figure().add_subplot(), estimate=truth)
    assert list(only) == ["estimate"]


def test_plot_covariance_ellipses_vertices_satisfy_the_ellipse(fig: Figure) -> None:
    ax = fig.add_subplot()
    rng = np.random.default_rng(0)
    means = rng.normal(size=(20, 2)) * 10.0
    a = rng.normal(size=(20, 2, 2))
    covs = a @ np.swapaxes(a, -1, -2) + 0.1 * np.eye(2)
    coll = plot_covariance_ellipses(ax, means, covs, n_sigma=3.0, every=4, color="green")
    assert isinstance(coll, PolyCollection)
    verts = polygon_vertices(coll)
    assert len(verts) == 5  # every 4th of 20
    for v, m, c in zip(verts, means[::4], covs[::4], strict=True):
        d = v - m
        q = np.einsum("ni,ni->n", d, np.linalg.solve(c, d.T).T)
        np.testing.assert_allclose(q, 9.0, rtol=1e-9)
    assert coll.get_facecolor().size == 0 or coll.get_facecolor()[0, 3] == 0.0  # unfilled
    np.testing.assert_allclose(coll.get_edgecolor()[0], to_rgba("green"))
    # Autoscaling took the ellipses into account.
    x0, x1 = ax.get_xlim()
    assert x0 <= float(min(v[:, 0].min() for v in verts))
    assert x1 >= float(max(v[:, 0].max() for v in verts))


def test_plot_covariance_ellipses_validates(fig: Figure) -> None:
    ax = fig.add_subplot()
    with pytest.raises(ShapeError):
        plot_covariance_ellipses(ax, np.zeros((3, 2)), np.tile(np.eye(2), (2, 1, 1)))
    with pytest.raises(CovarianceError):
        plot_covariance_ellipses(ax, np.zeros((1, 2)), -np.eye(2)[None])


def test_plot_landmarks_map_and_array(fig: Figure) -> None:
    ax = fig.add_subplot()
    lm = LandmarkMap(np.array([[1.0, 2.0], [3.0, -1.0], [0.0, 5.0]]), np.array([7, 3, 11]))
    artists = plot_landmarks(ax, lm, label="map", annotate_ids=True)
    scatter, *notes = artists
    np.testing.assert_array_equal(scatter.get_offsets(), lm.positions)
    assert [t.get_text() for t in notes] == ["7", "3", "11"]
    assert [t.xy for t in notes] == [(1.0, 2.0), (3.0, -1.0), (0.0, 5.0)]
    (only,) = plot_landmarks(ax, [[0.0, 0.0], [1.0, 1.0]], c="red")
    np.testing.assert_array_equal(only.get_offsets(), [[0.0, 0.0], [1.0, 1.0]])


def test_plot_landmark_estimates(fig: Figure) -> None:
    ax = fig.add_subplot()
    pos = np.array([[0.0, 0.0], [4.0, 1.0]])
    covs = np.stack([np.diag([0.04, 0.01]), np.diag([0.01, 0.09])])
    scatter, ellipses = plot_landmark_estimates(ax, pos, covs, n_sigma=3.0)
    np.testing.assert_array_equal(scatter.get_offsets(), pos)
    verts = polygon_vertices(ellipses)
    # Axis-aligned covariances: the 3σ ellipses reach exactly 3σ along x and y.
    np.testing.assert_allclose(np.ptp(verts[0], axis=0), [1.2, 0.6], rtol=1e-3)
    np.testing.assert_allclose(np.ptp(verts[1], axis=0), [0.6, 1.8], rtol=1e-3)
    assert len(plot_landmark_estimates(ax, pos)) == 1


def test_plot_segments(fig: Figure) -> None:
    ax = fig.add_subplot()
    seg = np.array([[[0.0, 0.0], [10.0, 0.0]], [[10.0, 0.0], [10.0, 5.0]]])
    coll = plot_segments(ax, SegmentMap(seg), lw=3.0)
    assert isinstance(coll, LineCollection)
    np.testing.assert_array_equal(np.array(coll.get_segments()), seg)
    assert coll.get_linewidth()[0] == 3.0
    np.testing.assert_array_equal(np.array(plot_segments(ax, seg).get_segments()), seg)


def test_plot_occupancy_grid_extent_and_orientation(fig: Figure) -> None:
    ax = fig.add_subplot()
    prob = np.full((4, 6), 0.5)
    prob[0, 0] = 1.0  # lower-left cell occupied
    prob[3, 5] = 0.0  # upper-right cell free
    grid = OccupancyGrid(prob, 0.5, np.array([-1.0, 2.0]))
    image = plot_occupancy_grid(ax, grid)
    xmin, ymin, xmax, ymax = grid.bounds()
    assert image.get_extent() == [xmin, xmax, ymin, ymax] == [-1.0, 2.0, 2.0, 4.0]
    assert image.origin == "lower"
    np.testing.assert_array_equal(image.get_array(), prob)
    # Colours: occupied black, free white, unknown mid grey.
    rgba = image.to_rgba(np.array([1.0, 0.0, 0.5]))
    np.testing.assert_allclose(rgba[0, :3], 0.0)
    np.testing.assert_allclose(rgba[1, :3], 1.0)
    assert 0.3 < rgba[2, 0] < 0.7
    # The occupied cell (0, 0) is the one containing the world point of its centre.
    centre = grid.cell_to_world([0, 0])
    assert tuple(grid.world_to_cell(centre)) == (0, 0)
    assert xmin < centre[0] < xmin + grid.resolution and ymin < centre[1] < ymin + 0.5


def test_plot_pose_errors(fig: Figure) -> None:
    axes = fig.subplots(3, 1, sharex=True)
    t = np.linspace(0.0, 10.0, 21)
    errors = np.stack([0.1 * np.sin(t), -0.2 * np.cos(t), np.full_like(t, 2 * np.pi + 0.01)], 1)
    sigmas = np.stack([np.full_like(t, 0.05), np.full_like(t, 0.1), np.full_like(t, 0.02)], 1)
    drawn = plot_pose_errors(axes, t, errors, sigmas, n_sigma=3.0)
    assert len(drawn) == 3 and all(len(d) == 2 for d in drawn)
    np.testing.assert_allclose(drawn[0][0].get_ydata(), errors[:, 0])
    # Heading wrapped (2π + 0.01 → 0.01) and shown in degrees.
    np.testing.assert_allclose(drawn[2][0].get_ydata(), math.degrees(0.01), rtol=1e-9)
    band = drawn[1][1].get_paths()[0].vertices
    np.testing.assert_allclose([band[:, 1].min(), band[:, 1].max()], [-0.3, 0.3])
    heading_band = drawn[2][1].get_paths()[0].vertices
    np.testing.assert_allclose(heading_band[:, 1].max(), math.degrees(0.06), rtol=1e-9)
    assert axes[2].get_ylabel() == "heading error [deg]"
    only_lines = plot_pose_errors(new_figure().subplots(3, 1), t, errors)
    assert all(len(d) == 1 for d in only_lines)
    with pytest.raises(ShapeError):
        plot_pose_errors(axes[:2], t, errors)


def test_plot_consistency(fig: Figure) -> None:
    ax = fig.add_subplot()
    t = np.arange(30.0)
    nees = np.random.default_rng(1).chisquare(3, size=30)
    lo, hi = chi2_gate(3, 0.025), chi2_gate(3, 0.975)
    band, line = plot_consistency(ax, t, nees, (lo, hi), label="NEES")
    np.testing.assert_array_equal(line.get_ydata(), nees)
    v = band.get_paths()[0].vertices
    np.testing.assert_allclose([v[:, 1].min(), v[:, 1].max()], [lo, hi])
    np.testing.assert_allclose([v[:, 0].min(), v[:, 0].max()], [0.0, 29.0])
    assert ax.get_ylabel() == "NEES"
    with pytest.raises(InputError):
        plot_consistency(ax, t, nees, (hi, lo))
    with pytest.raises(ShapeError):
        plot_consistency(ax, t, nees, (np.zeros(3), np.ones(3)))


def test_save_figure_writes_png_atomically(fig: Figure, tmp_path: Path) -> None:
    plot_trajectory(fig.add_subplot(), circle_poses())
    out = save_figure(fig, tmp_path / "sub" / "trajectory.png")
    assert out == tmp_path / "sub" / "trajectory.png"
    data = out.read_bytes()
    assert len(data) > 100 and data.startswith(PNG_SIGNATURE)
    assert [p.name for p in out.parent.iterdir()] == ["trajectory.png"]  # no temp file left
    # Overwriting replaces the file; a failing save leaves the old file and no temp file.
    save_figure(fig, out)
    with pytest.raises(ValueError):
        save_figure(fig, out, fmt="no-such-format")
    assert out.read_bytes().startswith(PNG_SIGNATURE)
    assert [p.name for p in out.parent.iterdir()] == ["trajectory.png"]
    pdf = save_figure(fig, tmp_path / "trajectory.pdf")
    assert pdf.read_bytes().startswith(b"%PDF")
