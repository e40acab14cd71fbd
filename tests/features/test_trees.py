"""The trunk extractor on exactly ray-cast scans of known circles and walls."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.errors import ConfigError, InputError, ShapeError
from slamkit.features import TreeExtractorConfig, extract_trees
from slamkit.sim import trunk_scan

ANGLES = np.deg2rad(np.arange(361) * 0.5 - 90.0)  # Victoria Park's 180° at 0.5°


def _polar(cx: float, cy: float) -> tuple[float, float]:
    return float(np.hypot(cx, cy)), float(np.arctan2(cy, cx))


def _match(det, cx: float, cy: float) -> int:
    d = np.hypot(det.points()[:, 0] - cx, det.points()[:, 1] - cy)
    assert d.size and d.min() < 0.5, f"no detection near ({cx}, {cy})"
    return int(np.argmin(d))


@pytest.mark.parametrize(
    ("distance", "diameter", "centre_bound", "diameter_bound"),
    [
        (5.0, 0.3, 0.03, 0.04),  # many beams: circle fit
        (10.0, 0.5, 0.05, 0.06),
        (15.0, 0.4, 0.15, 0.15),  # 3 beams: angular width
        (25.0, 0.6, 0.25, 0.25),
    ],
)
def test_centre_and_diameter_of_a_lone_trunk_within_bounds(
    distance, diameter, centre_bound, diameter_bound
):
    # Bounds: a beam of width δ = 0.5° at range r misplaces each edge by up to r δ / 2
    # (5 m: 2.2 cm; 25 m: 11 cm on each side).
    errors_c, errors_d = [], []
    for bearing in np.deg2rad(np.linspace(-60, 60, 13) + 0.17):
        cx, cy = distance * np.cos(bearing), distance * np.sin(bearing)
        scan = trunk_scan(ANGLES, [(cx, cy, diameter / 2)])
        det = extract_trees(scan, ANGLES)
        assert len(det) == 1
        errors_c.append(float(np.hypot(*(det.points()[0] - (cx, cy)))))
        errors_d.append(abs(float(det.diameters[0]) - diameter))
    assert max(errors_c) < centre_bound
    assert max(errors_d) < diameter_bound


def test_noisy_scan_of_a_grove_finds_every_trunk():
    rng = np.random.default_rng(4)
    trunks = [(6.0, 2.0, 0.2), (12.0, -4.0, 0.25), (20.0, 8.0, 0.3), (9.0, 9.0, 0.15)]
    found, err = 0, []
    for _ in range(20):
        scan = trunk_scan(ANGLES, trunks, range_sigma=0.02, rng=rng)
        det = extract_trees(scan, ANGLES)
        assert len(det) == len(trunks)  # nothing extra
        for cx, cy, rad in trunks:
            k = _match(det, cx, cy)
            found += 1
            err.append(abs(float(det.diameters[k]) - 2 * rad))
    assert found == 80
    assert float(np.median(err)) < 0.08


def test_walls_and_long_segments_give_no_trunk():
    walls = [
        (3.0, -10.0, 3.0, 10.0),  # a wall across the view
        (5.0, 12.0, 30.0, 12.0),  # a wall along the drive, seen at grazing angles
        (8.0, -6.0, 8.5, -6.2),  # a short board, 0.54 m wide but flat and deep at 10 m
    ]
    scan = trunk_scan(ANGLES, [], walls[:2])
    assert len(extract_trees(scan, ANGLES)) == 0
    # A corner (two walls meeting away from the laser) is concave: no trunk.
    corner = [(10.0, -3.0, 12.0, 0.0), (12.0, 0.0, 10.0, 3.0)]
    assert len(extract_trees(trunk_scan(ANGLES, [], corner), ANGLES)) == 0


def test_occluded_trunk_is_refused_and_the_one_in_front_is_kept():
    # A trunk at 10 m half hidden behind one at 5 m: the hidden one's width is not its own.
    front, back = (5.0, 0.0, 0.2), (10.0, 0.35, 0.3)
    scan = trunk_scan(ANGLES, [front, back])
    det = extract_trees(scan, ANGLES)
    assert len(det) == 1
    k = _match(det, 5.0, 0.0)
    assert abs(det.diameters[k] - 0.4) < 0.05


def test_trunk_against_a_wall_close_behind_is_refused():
    # Less than the jump (1 m) in front of the wall: no occlusion edge, not isolated.
    scan = trunk_scan(ANGLES, [(7.0, 0.0, 0.2)], [(7.5, -5.0, 7.5, 5.0)])
    assert len(extract_trees(scan, ANGLES)) == 0
    scan = trunk_scan(ANGLES, [(7.0, 0.0, 0.2)], [(9.5, -5.0, 9.5, 5.0)])
    assert len(extract_trees(scan, ANGLES)) == 1


def test_trunks_beyond_max_range_or_at_the_scan_edge_are_not_reported():
    far = trunk_scan(ANGLES, [(45.0, 0.0, 0.3)])
    assert len(extract_trees(far, ANGLES)) == 0
    edge = trunk_scan(ANGLES, [(0.0, -6.0, 0.3)])  # centred on the first beam
    assert len(extract_trees(edge, ANGLES)) == 0
    assert len(extract_trees(far, ANGLES, TreeExtractorConfig(max_range=60.0))) == 1


def test_bad_input_is_refused():
    with pytest.raises(ShapeError):
        extract_trees(np.ones(5), ANGLES)
    with pytest.raises(InputError, match="evenly spaced"):
        extract_trees(np.ones(3), [0.0, 0.1, 0.3])
    with pytest.raises(ConfigError, match="max_diameter"):
        TreeExtractorConfig(min_diameter=0.5, max_diameter=0.4)
    with pytest.raises(ConfigError, match="fit_beams"):
        TreeExtractorConfig(fit_beams=2)


def test_trunk_scan_ray_casts_exactly():
    scan = trunk_scan(ANGLES, [(10.0, 0.0, 0.5)], [(0.0, 4.0, 4.0, 4.0)], max_range=30.0)
    assert scan[180] == pytest.approx(9.5, abs=1e-12)  # straight ahead: the near side
    assert scan[360] == pytest.approx(4.0, abs=1e-12)  # straight left: the wall
    assert scan[0] == 30.0  # straight right: nothing
