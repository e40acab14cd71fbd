"""Each picture the first-hour review found wrong, checked by what it draws: axis limits,
the map layer, markers, legend placement, particle counts, frames, sizes."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from matplotlib.collections import LineCollection, PathCollection
from matplotlib.image import AxesImage
from matplotlib.lines import Line2D
from PIL import Image

from slamkit.datasets import load_dataset
from slamkit.estimation.contract import Frame
from slamkit.maps import OccupancyGrid
from slamkit.optim.data import EdgeSet, GraphData
from slamkit.pipeline import EstimatorOutput, ParticleSnapshot, run
from slamkit.pipeline.evaluate import evaluate
from slamkit.viz import new_figure, save_figure
from slamkit.viz.animation import PARTICLES_DRAWN, animation_frames
from slamkit.viz.graphs import pose_graph_figure, principal_plane
from slamkit.viz.layout import crop_to_known, known_box, pick_frames, robust_box
from slamkit.viz.maps import plot_map
from slamkit.viz.report import FIGURE_DPI, run_figures
from slamkit.viz.run_views import PARTICLES_DRAWN as PANEL_PARTICLES
from slamkit.viz.run_views import loop_closures


@pytest.fixture(scope="module")
def five():  # type: ignore[no-untyped-def]
    ds = load_dataset("five-features", seed=0)
    return ds, run("ekf-slam", ds)


def _lines(ax, label: str) -> list[Line2D]:  # type: ignore[no-untyped-def]
    return [ln for ln in ax.get_lines() if ln.get_label() == label]


def _truth_box(ds):  # type: ignore[no-untyped-def]
    return robust_box(np.concatenate([ds.truth.poses[:, :2], ds.truth.landmarks.positions]))


def test_a_huge_prior_ellipse_does_not_set_the_limits(five) -> None:  # type: ignore[no-untyped-def]
    ds, res = five
    covs = res.covariances.copy()
    covs[0] = np.diag([3000.0**2, 3000.0**2, 1.0])  # the ±3 km prior of mrclam1
    res = replace(res, covariances=covs)
    fig = run_figures(res, ds, evaluate(res, ds))["trajectory.png"]
    ax = fig.axes[0]
    xmin, xmax, ymin, ymax = _truth_box(ds)
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert xmin - 2 < x0 <= xmin and xmax <= x1 < xmax + 2  # the arena, not ±9 km
    assert ymin - 2 < y0 <= ymin and ymax <= y1 < ymax + 2


def test_a_lost_start_does_not_flatten_the_errors_or_the_map(five) -> None:  # type: ignore[no-untyped-def]
    ds, res = five
    poses = res.poses.copy()
    poses[:4, :2] += 400.0  # the first samples of a global start: hundreds of metres off
    res = replace(res, poses=poses)
    figs = run_figures(res, ds, evaluate(res, ds))
    x_err = figs["errors.png"].axes[0]
    assert x_err.get_ylim()[1] < 2.0  # the run after the transient fills the axis
    line = x_err.get_lines()[0]
    assert line.get_xdata()[0] == pytest.approx(0.0)  # time from the start
    assert x_err.get_xlabel() == "" and "since the start" in figs["errors.png"].axes[2].get_xlabel()
    ax = figs["trajectory.png"].axes[0]
    assert ax.get_xlim()[1] < 20.0 and ax.get_ylim()[1] < 20.0


def test_truth_dashed_over_the_estimate_start_end_and_legend_beside(five) -> None:  # type: ignore[no-untyped-def]
    ds, res = five
    fig = run_figures(res, ds, evaluate(res, ds))["trajectory.png"]
    ax = fig.axes[0]
    (truth,) = _lines(ax, "ground truth")
    (est,) = _lines(ax, "estimate")
    assert truth.get_linestyle() == "--" and truth.get_zorder() > est.get_zorder()
    (start,) = _lines(ax, "start")
    (end,) = _lines(ax, "end")
    np.testing.assert_allclose(start.get_xydata()[0], res.poses[0, :2])
    np.testing.assert_allclose(end.get_xydata()[0], res.poses[-1, :2])
    fig.canvas.draw()
    legend = ax.get_legend()
    assert legend.get_window_extent().x0 >= ax.get_window_extent().x1  # off the data


def _grid_with_a_room() -> OccupancyGrid:
    """A 100 m x 80 m grid (0.1 m cells) of which only a 6 m x 4 m room was observed."""
    prob = np.full((800, 1000), 0.5)
    prob[300:340, 500:560] = 0.1  # free floor at x 50..56, y 30..34
    prob[[300, 339], 500:560] = 0.9  # walls all round
    prob[300:340, [500, 559]] = 0.9
    prob[340:500, 520:530] = 0.35  # a free ray out through a door: not what the crop is for
    return OccupancyGrid(prob, 0.1, np.array([0.0, 0.0]))


def test_occupancy_maps_are_cropped_to_known_cells_with_a_scale_bar() -> None:
    grid = _grid_with_a_room()
    assert known_box(grid) == pytest.approx((50.0, 56.0, 30.0, 50.0))  # with the ray
    cropped = crop_to_known(grid, margin=1.0)
    assert cropped.bounds() == pytest.approx((49.0, 29.0, 57.0, 35.0))
    np.testing.assert_array_equal(cropped.prob[10:50, 10:70], grid.prob[300:340, 500:560])
    ax = new_figure().add_subplot()
    image = plot_map(ax, grid)
    assert image.get_extent() == pytest.approx([49.0, 57.0, 29.0, 35.0])
    assert ax.get_xlabel() == "x [m]"
    bars = [a for a in ax.artists if type(a).__name__ == "AnchoredSizeBar"]
    assert len(bars) == 1
    assert bars[0].txt_label.get_text() in ("1 m", "2 m")  # a round length near 1/5 of 8 m


def test_the_map_is_drawn_under_the_run(five) -> None:  # type: ignore[no-untyped-def]
    ds, res = five
    grid = OccupancyGrid(np.full((60, 80), 0.2), 0.25, np.array([-4.0, -3.0]))
    res = replace(res, output=replace(res.output, grid=grid))
    figs = run_figures(res, ds, evaluate(res, ds))
    for name in ("trajectory.png", "map.png"):
        ax = figs[name].axes[0]
        images = [a for a in ax.get_children() if isinstance(a, AxesImage)]
        assert len(images) == 1, name
        assert images[0].get_zorder() < min(ln.get_zorder() for ln in ax.get_lines())


def test_least_squares_fixes_are_points() -> None:
    ds = load_dataset("five-features", seed=0)
    res = run("least-squares", ds)
    fig = run_figures(res, ds, evaluate(res, ds))["trajectory.png"]
    (fixes,) = _lines(fig.axes[0], "least-squares fixes")
    assert fixes.get_linestyle() == "None" and fixes.get_marker() == "."
    assert _lines(fig.axes[0], "estimate") == []


def _with_particles(res, ds, n: int, spread: float = 0.3):  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(1)
    snaps = tuple(
        ParticleSnapshot(
            float(res.times[i]),
            ds.truth.poses[i] + rng.normal(0, spread, (n, 3)),
            np.full(n, 1.0 / n),
        )
        for i in (0, 120, 240)
    )
    return replace(res, output=replace(res.output, particle_snapshots=snaps))


def test_the_particle_view_zooms_to_the_cloud_and_labels_it(five) -> None:  # type: ignore[no-untyped-def]
    ds, res = five
    res = _with_particles(res, ds, 10_000)
    fig = run_figures(res, ds, evaluate(res, ds))["particles.png"]
    panels = [ax for ax in fig.axes if ax.get_visible()]
    assert len(panels) == 3
    scene = _truth_box(ds)
    for ax, i in zip(panels, (0, 120, 240), strict=True):
        cloud = [c for c in ax.collections if str(c.get_label()).startswith("particles")]
        assert len(cloud) == 1
        assert 0 < cloud[0].get_offsets().shape[0] <= PANEL_PARTICLES
        x0, x1 = ax.get_xlim()
        assert x0 < ds.truth.poses[i, 0] < x1
        assert x1 - x0 < 0.6 * (scene[1] - scene[0])  # zoomed in, not the whole scene
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "estimate so far" in labels and any(t.startswith("particles") for t in labels)


def test_animation_thins_particles_shows_the_pose_and_never_the_future(five) -> None:  # type: ignore[no-untyped-def]
    ds, res = five
    rng = np.random.default_rng(2)
    frames = tuple(
        Frame(
            float(res.times[i]),
            res.poses[i],
            res.covariances[i],
            particles=res.poses[i] + rng.normal(0, 0.5, (50_000, 3)),
        )
        for i in range(0, len(res), 10)
    )
    fig, draw, count = animation_frames(replace(res, frames=frames), ds, max_frames=20)
    assert count == 20
    ax = fig.axes[0]
    changed = draw(0)
    (truth,) = _lines(ax, "ground truth")
    assert len(truth.get_xdata()) <= 2  # frame 0: the true path up to t0, not all of it
    scatter = [a for a in changed if isinstance(a, PathCollection)]
    assert len(scatter) == 1 and scatter[0].get_offsets().shape[0] <= PARTICLES_DRAWN
    assert any(type(a).__name__ == "FancyArrow" for a in changed)  # the current pose
    draw(count - 1)
    seen = int(np.searchsorted(ds.truth.times, frames[-1].t, side="right"))
    assert len(truth.get_xdata()) == seen  # the last frame: the true path up to its time


def test_pick_frames_follows_the_motion() -> None:
    t = np.arange(100.0)
    xy = np.zeros((100, 2))
    xy[50:, 0] = np.arange(50.0) * 2.0  # still for 50 s, then moving
    idx = pick_frames(t, xy, 21)
    assert idx[0] == 0 and idx[-1] == 99
    assert np.sum(idx >= 50) > np.sum(idx < 50)  # more frames while moving


def test_pngs_are_large_and_svg_on_request(five, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    ds, res = five
    fig = run_figures(res, ds, evaluate(res, ds))["trajectory.png"]
    png = save_figure(fig, tmp_path / "trajectory.png", dpi=FIGURE_DPI)
    with Image.open(png) as im:
        assert im.size[0] >= 1200 and im.size[1] >= 900
    assert png.stat().st_size > 50_000
    svg = save_figure(fig, tmp_path / "trajectory.svg")
    assert b"<svg" in svg.read_bytes()[:2000]


def test_the_scale_bar_goes_where_it_hides_the_least() -> None:
    """Walls (an image's dark cells) and a path in the lower right: the bar goes to the
    lower left, which is empty, and has no box; with every corner empty it stays in the
    lower right."""
    from slamkit.viz.layout import add_scale_bar, emptiest_corner

    prob = np.full((100, 100), 0.5)
    prob[:12, 75:] = 1.0  # a wall block in the lower right (cells of 0.1 m)
    grid = OccupancyGrid(prob, 0.1, np.array([0.0, 0.0]))
    ax = new_figure().add_subplot()
    plot_map(ax, grid, crop=False, scale_bar=False)
    ax.plot([8.0, 9.5], [0.5, 0.5])
    ax.set_xlim(0.0, 10.0)
    ax.set_ylim(0.0, 10.0)
    assert emptiest_corner(ax) == "lower left"
    bar = add_scale_bar(ax)
    assert bar.loc == 3 and not bar.patch.get_visible()  # 3: lower left
    empty = new_figure().add_subplot()
    empty.set_xlim(0.0, 10.0)
    assert emptiest_corner(empty) == "lower right"


def test_a_3d_graph_is_shown_on_its_principal_plane_on_one_scale() -> None:
    rng = np.random.default_rng(3)
    uv = rng.uniform(-10, 10, (200, 2)) * [3.0, 1.0]
    plane = np.stack([uv[:, 0], np.zeros(200), uv[:, 1]], axis=1)  # the x-z plane: x-y is a line
    plane -= plane.mean(axis=0)
    p0, p1, labels = principal_plane(plane * 1.5, plane)
    assert np.ptp(p1[:, 1]) > 15.0  # both axes of the projection carry the spread
    assert "≈x" in labels[0] and "≈z" in labels[1]
    np.testing.assert_allclose(np.abs(p0), 1.5 * np.abs(p1), atol=1e-9)
    fig = pose_graph_figure(p0, p1, axis_labels=labels)
    ax0, ax1 = fig.axes
    assert ax0.get_xlim() == ax1.get_xlim() and ax0.get_ylim() == ax1.get_ylim()
    assert ax0.get_xlim()[1] >= p0[:, 0].max()


def _chain_graph(n: int, closures: list[tuple[int, int]], neighbours: int) -> GraphData:
    pairs = [(k, k + 1) for k in range(n - 1)]
    pairs += [(k, k + g) for k in range(n) for g in range(2, neighbours + 2) if k + g < n]
    pairs += closures
    i, j = np.array(pairs).T
    e = len(pairs)
    edges = EdgeSet(
        "se2", i, j, np.zeros((e, 3)), np.tile(np.eye(3), (e, 1, 1)), np.zeros(e, dtype=np.int64)
    )
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    poses = np.stack([10 * np.cos(ang), 10 * np.sin(ang), ang], axis=1)
    return GraphData(2, np.arange(n), poses, edges=(edges,))


def test_loop_closures_are_the_far_edges_and_are_drawn_over_the_map(five) -> None:  # type: ignore[no-untyped-def]
    near = _chain_graph(40, [(0, 38), (5, 30)], neighbours=4)
    assert loop_closures(near).shape[0] > 2  # edges between near poses too
    np.testing.assert_array_equal(loop_closures(near, min_gap=6), [[0, 38], [5, 30]])
    graph = _chain_graph(40, [(0, 38), (5, 30)], neighbours=0)
    ds, res = five
    grid = OccupancyGrid(np.full((100, 100), 0.2), 0.25, np.array([-12.0, -12.0]))
    res = replace(res, output=EstimatorOutput(graph=graph, grid=grid))
    figs = run_figures(res, ds, evaluate(res, ds))
    ax = figs["loops.png"].axes[0]
    (coll,) = [
        c
        for c in ax.collections
        if isinstance(c, LineCollection) and str(c.get_label()).startswith("loop closures")
    ]
    assert coll.get_label() == "loop closures (2)" and len(coll.get_segments()) == 2
    assert any(isinstance(a, AxesImage) for a in ax.get_children())
    assert "2 accepted loop closures" in ax.get_title()
