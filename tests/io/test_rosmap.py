"""ROS map_server files (PGM + YAML) and map images: round trip, orientation, errors."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.errors import DatasetFormatError, InputError
from slamkit.io.rosmap import read_ros_map, trinary_pixels, write_ros_map
from slamkit.io.rosmap_read import read_ros_map_reading
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


_ONE = b"P5\n1 1\n255\n\x00"


@pytest.mark.parametrize(
    ("yaml", "pgm", "message", "line"),
    [
        ("image: x.pgm\nresolution: 0.1\n", b"P6\n1 1\n255\n000", "P5' binary or 'P2'", None),
        ("image: x.pgm\nresolution: 0.1\n", b"\x89PNG\r\n\x1a\n", "a PNG", None),
        ("image: x.pgm\nresolution: 0.1\n", b"P5\n2 2\n255\n\x00", "expected 4 pixel", None),
        ("image: x.pgm\nresolution: 0.1\n", b"P5\n2 2\n65535\n\x00", "16-bit", None),
        ("image: x.pgm\nresolution: 0.1\n", b"P5\n2", "ends before its height", None),
        ("image: x.pgm\nresolution: 0.1\n", b"P5\n1 1\n99\n\xff", "above maxval 99", None),
        ("image: x.pgm\nresolution: 0.1\n", b"P2\n2 1\n255\n0 1 2\n", "expected 2 pixel", None),
        ("image: x.pgm\nresolution: 0.1\n", b"P2\n1 1\n255\nzero\n", "integers", None),
        ("image: x.pgm\nresolution: 0.1\norigin: [0, 0]\n", _ONE, "origin: expected", 3),
        ("image: x.pgm\nresolution: 0.1\norigin:\n", _ONE, "key: value", 3),
        ("image: x.pgm\n", _ONE, "missing 'resolution'", None),
        ("resolution: 0.1\n", _ONE, "missing 'image'", None),
        ("", _ONE, "empty map description", None),
        ("image: x.pgm\nresolution: fine\n", _ONE, "expected a number", 2),
        ("image: x.pgm\nresolution: -0.1\n", _ONE, "resolution: expected a number > 0", 2),
        ("image: x.pgm\nresolution 0.1\n", _ONE, "key: value", 2),
        ("image: x.pgm\nresolution: 0.1\nresolution: 0.2\n", _ONE, "twice .first on line 2", 3),
        ("image: y.pgm\nresolution: 0.1\n", _ONE, "image: no such file", 1),
        ("image: x.pgm\nresolution: 0.1\nmode: fancy\n", _ONE, "mode: expected one of", 3),
        ("image: x.pgm\nresolution: 0.1\nnegate: 2\n", _ONE, "negate: expected 0 or 1", 3),
        ("image: x.pgm\nresolution: 0.1\nfree_thresh: 0.7\n", _ONE, "free_thresh < occ", 3),
        ("image: x.pgm\nresolution: nan\n", _ONE, "finite", 2),
    ],
)  # fmt: skip
def test_reader_errors_name_the_file_and_line(tmp_path, yaml, pgm, message, line):
    (tmp_path / "x.pgm").write_bytes(pgm)
    (tmp_path / "x.yaml").write_text(yaml)
    with pytest.raises(DatasetFormatError, match=message) as info:
        read_ros_map(tmp_path / "x.yaml")
    assert info.value.line == line
    assert "\n" not in str(info.value)  # one line
    # the YAML's errors name the YAML, the image's the image
    want = (
        "x.pgm" if yaml.startswith("image: x.pgm\nresolution: 0.1\n") and line is None else "x.yaml"
    )
    assert info.value.path == tmp_path / want


def test_map_saver_files_read_as_map_server_reads_them(tmp_path):
    """ROS's map_saver: 0 occupied, 254 free, 205 unknown, free_thresh 0.196; a P2 (text) image
    with comments; a rotated origin read unrotated with a note; unknown keys noted; extra
    bytes after the pixels noted."""
    (tmp_path / "m.pgm").write_bytes(b"P2\n# CREATOR: map_saver\n3 2\n255\n0 254 205\n205 0 254\n")
    (tmp_path / "m.yaml").write_text(
        "# saved by map_saver\nimage: m.pgm\nresolution: 0.050000\n"
        "origin: [-1.000000, 2.500000, 0.300000]\nnegate: 0\noccupied_thresh: 0.65\n"
        "free_thresh: 0.196\nunknown_key: 3\n"
    )
    reading = read_ros_map_reading(tmp_path / "m.yaml")
    # bottom image row first in the grid
    np.testing.assert_array_equal(reading.grid.prob, [[UNKNOWN, 1.0, 0.0], [1.0, 0.0, UNKNOWN]])
    np.testing.assert_array_equal(reading.grid.origin_xy, [-1.0, 2.5])
    assert reading.grid.resolution == 0.05 and reading.mode == "trinary"
    assert len(reading.notes) == 2
    assert "m.yaml:4: origin yaw 0.3 rad ignored" in reading.notes[0]
    assert "m.yaml:8: key 'unknown_key'" in reading.notes[1]
    # the same image as P5 with two stray bytes after the pixels
    img = bytes([0, 254, 205, 205, 0, 254])
    (tmp_path / "b.pgm").write_bytes(b"P5 3 2 255\n" + img + b"\n\n")
    (tmp_path / "b.yaml").write_text("image: b.pgm\nresolution: 0.05\nfree_thresh: 0.196\n")
    back = read_ros_map_reading(tmp_path / "b.yaml")
    np.testing.assert_array_equal(back.grid.prob, reading.grid.prob)
    assert back.notes == ("b.pgm: 2 bytes after the last pixel ignored",)


def test_scale_and_raw_modes(tmp_path):
    # p = (255 - v)/255: v=0 -> 1 (occupied), 255 -> 0 (free), 128 -> 0.498 (between)
    (tmp_path / "s.pgm").write_bytes(b"P5\n4 1\n255\n" + bytes([0, 255, 128, 40]))
    (tmp_path / "s.yaml").write_text(
        "image: s.pgm\nresolution: 1\noccupied_thresh: 0.65\nfree_thresh: 0.35\nmode: scale\n"
    )
    p_mid = (255 - 128) / 255
    want = [[1.0, 0.0, 0.99 * (p_mid - 0.35) / 0.30, 1.0]]
    np.testing.assert_allclose(read_ros_map(tmp_path / "s.yaml").prob, want, rtol=1e-12)
    # raw: the value is the occupancy in percent; above 100 unknown
    (tmp_path / "r.pgm").write_bytes(b"P5\n4 1\n255\n" + bytes([0, 100, 37, 255]))
    (tmp_path / "r.yaml").write_text("image: r.pgm\nresolution: 1\nmode: raw\nnegate: 1\n")
    np.testing.assert_array_equal(read_ros_map(tmp_path / "r.yaml").prob, [[0.0, 1.0, 0.37, 0.5]])
    # a PGM of maxval 100 scales to 255 before decoding
    (tmp_path / "c.pgm").write_bytes(b"P5\n2 1\n100\n" + bytes([0, 100]))
    (tmp_path / "c.yaml").write_text("image: c.pgm\nresolution: 1\n")
    np.testing.assert_array_equal(read_ros_map(tmp_path / "c.yaml").prob, [[1.0, 0.0]])


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
