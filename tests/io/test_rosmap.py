"""ROS map_server files (PGM + YAML) and map images: round trip, orientation, errors."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.errors import DatasetFormatError, InputError
from slamkit.io.rosmap import read_ros_map, trinary_pixels, write_ros_map
from slamkit.mapping.quality import (
    FREE_THRESHOLD,
    OCCUPIED_THRESHOLD,
    classify_grid,
    map_quality,
)
from slamkit.maps import UNKNOWN, OccupancyGrid


def _grid(rng: np.random.Generator, rows: int = 7, cols: int = 11) -> OccupancyGrid:
    prob = rng.choice([0.0, UNKNOWN, 1.0], size=(rows, cols))
    return OccupancyGrid(prob, 0.05, np.array([-1.25, 3.4]))


def test_round_trip_is_exact_for_a_trinary_grid(tmp_path, rng):
    grid = _grid(rng)
    _, yml = write_ros_map(grid, tmp_path / "map.pgm")
    assert yml == tmp_path / "map.yaml"
    back = read_ros_map(yml)
    np.testing.assert_array_equal(back.prob, grid.prob)
    assert back.resolution == grid.resolution
    np.testing.assert_array_equal(back.origin_xy, grid.origin_xy)


def test_round_trip_classifies_other_probabilities(tmp_path):
    prob = np.array([[0.0, 0.2, 0.35, 0.36], [0.5, 0.64, 0.65, 0.99]])
    grid = OccupancyGrid(prob, 0.1, np.zeros(2))
    write_ros_map(grid, tmp_path / "m.pgm")
    back = read_ros_map(tmp_path / "m.yaml")
    np.testing.assert_array_equal(back.prob, [[0.0, 0.0, 0.0, 0.5], [0.5, 0.5, 1.0, 1.0]])


def test_pgm_bytes_header_and_row_order(tmp_path):
    prob = np.full((2, 3), UNKNOWN)
    prob[0, 0] = 1.0  # bottom-left cell of the grid …
    prob[1, 2] = 0.0  # … and top-right
    pgm, yml = write_ros_map(OccupancyGrid(prob, 0.5, np.array([2.0, -1.0])), tmp_path / "a.pgm")
    data = pgm.read_bytes()
    assert data.startswith(b"P5\n# ")
    header_end = data.index(b"\n3 2\n255\n") + len(b"\n3 2\n255\n")
    pixels = np.frombuffer(data[header_end:], dtype=np.uint8).reshape(2, 3)
    # Image rows go down: the grid's top row comes first.
    np.testing.assert_array_equal(pixels, [[128, 128, 255], [0, 128, 128]])
    text = yml.read_text()
    assert "image: a.pgm\n" in text
    assert "resolution: 0.5\n" in text
    assert "origin: [2.0, -1.0, 0.0]\n" in text
    assert "negate: 0\n" in text and "occupied_thresh: 0.65\n" in text
    assert "free_thresh: 0.35\n" in text


def test_yaml_thresholds_are_the_quality_report_thresholds(tmp_path, rng):
    """One convention: the YAML carries the thresholds the cells were classified with (those
    of ``quality.json``), and a map_server reading the file back with them finds the same
    occupied, free and unknown cells as :func:`classify_grid`."""
    grid = OccupancyGrid(rng.uniform(0.0, 1.0, size=(40, 30)), 0.05)
    _, yml = write_ros_map(grid, tmp_path / "q.pgm")
    fields = dict(line.split(": ", 1) for line in yml.read_text().splitlines())
    q = map_quality(grid)
    assert float(fields["occupied_thresh"]) == q.occupied_threshold == OCCUPIED_THRESHOLD
    assert float(fields["free_thresh"]) == q.free_threshold == FREE_THRESHOLD
    back = read_ros_map(yml)
    cls = classify_grid(grid)
    np.testing.assert_array_equal(back.prob == 1.0, cls == 2)
    np.testing.assert_array_equal(back.prob == 0.0, cls == 1)
    np.testing.assert_array_equal(back.prob == UNKNOWN, cls == 0)
    # other thresholds are written too, and still decode the three pixels
    _, yml = write_ros_map(grid, tmp_path / "t.pgm", occupied_threshold=0.9, free_threshold=0.1)
    assert "occupied_thresh: 0.9\n" in yml.read_text() and "free_thresh: 0.1\n" in yml.read_text()
    np.testing.assert_array_equal(read_ros_map(yml).prob == 0.0, grid.prob <= 0.1)


def test_reader_follows_map_server_thresholds(tmp_path):
    # p = (255 - v) / 255: 10 -> 0.96 occupied, 100 -> 0.61 unknown, 250 -> 0.02 free.
    img = np.array([[10, 100, 250]], dtype=np.uint8)
    (tmp_path / "x.pgm").write_bytes(b"P5\n3 1\n255\n" + img.tobytes())
    (tmp_path / "x.yaml").write_text(
        "image: x.pgm\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    np.testing.assert_array_equal(read_ros_map(tmp_path / "x.yaml").prob, [[1.0, 0.5, 0.0]])
    (tmp_path / "y.yaml").write_text("image: x.pgm\nresolution: 0.1\nnegate: 1\n")
    np.testing.assert_array_equal(read_ros_map(tmp_path / "y.yaml").prob, [[0.0, 0.5, 1.0]])


@pytest.mark.parametrize(
    ("yaml", "pgm", "message", "line"),
    [
        ("image: x.pgm\nresolution: 0.1\n", b"P2\n1 1\n255\n0", "binary PGM", None),
        ("image: x.pgm\nresolution: 0.1\n", b"P5\n2 2\n255\n\x00", "expected 4 pixel", None),
        ("image: x.pgm\nresolution: 0.1\norigin: [0, 0, 0.3]\n", b"P5\n1 1\n255\n\x00",
         "rotated", 3),
        ("image: x.pgm\n", b"P5\n1 1\n255\n\x00", "missing 'resolution'", None),
        ("image: x.pgm\nresolution: fine\n", b"P5\n1 1\n255\n\x00", "expected a number", 2),
        ("image: x.pgm\nresolution 0.1\n", b"P5\n1 1\n255\n\x00", "key: value", 2),
    ],
)  # fmt: skip
def test_reader_errors_name_the_file(tmp_path, yaml, pgm, message, line):
    (tmp_path / "x.pgm").write_bytes(pgm)
    (tmp_path / "x.yaml").write_text(yaml)
    with pytest.raises(DatasetFormatError, match=message) as info:
        read_ros_map(tmp_path / "x.yaml")
    assert info.value.line == line


def test_trinary_pixels_checks_thresholds():
    grid = OccupancyGrid(np.zeros((1, 1)), 1.0)
    with pytest.raises(InputError, match="thresholds"):
        trinary_pixels(grid, occupied_threshold=0.3, free_threshold=0.4)
    # the unknown grey (p = 0.498) would decode as free under free_thresh 0.6
    with pytest.raises(InputError, match=r"0\.498 < occupied"):
        trinary_pixels(grid, occupied_threshold=0.8, free_threshold=0.6)


def test_map_image_png_orientation_and_axes(tmp_path):
    pytest.importorskip("matplotlib")
    from matplotlib.image import imread

    from slamkit.viz import new_figure
    from slamkit.viz.maps import map_image, plot_map, save_map_image

    prob = np.full((3, 4), UNKNOWN)
    prob[0, :] = 1.0  # the bottom row of the grid is a wall
    prob[2, 3] = 0.0  # the top-right cell is free
    grid = OccupancyGrid(prob, 0.5, np.array([1.0, 2.0]))
    img = map_image(grid)
    np.testing.assert_array_equal(img[-1], [0, 0, 0, 0])  # bottom of the picture: the wall
    assert img[0, 3] == 255 and img[1, 1] == 128
    path = save_map_image(grid, tmp_path / "m.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    back = imread(path)
    assert back.shape == (3, 4)  # one 8-bit grey channel, one pixel per cell
    np.testing.assert_allclose(back, img / 255.0, atol=1 / 255)
    fig = new_figure()
    ax = fig.add_subplot()
    artist = plot_map(ax, grid, trajectory=np.array([[1.5, 2.5, 0.0], [2.5, 3.0, 0.1]]))
    assert artist.get_extent() == [1.0, 3.0, 2.0, 3.5]
    assert len(ax.lines) == 1
