"""Laser odometry: wheel odometry as the prior, scan matching against a point map or the
last keyframe."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from slamkit.config import config_from_mapping
from slamkit.datasets import Control, LaserScan, load_dataset
from slamkit.errors import ConfigError, InputError
from slamkit.geometry.angles import wrap_angle
from slamkit.localization.laser_odometry import LaserOdometry, LaserOdometryConfig
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate


@pytest.fixture(scope="module")
def rooms() -> list:
    return [load_dataset("rooms-laser", seed=s) for s in (0, 1, 2)]


@pytest.mark.parametrize("reference", ["map", "keyframe"])
def test_scan_matching_corrects_the_drift_of_dead_reckoning(rooms, reference) -> None:
    """On the simulated rooms (3 cm range noise, noisy controls), seeds 0-2: the trajectory
    error is well below dead reckoning's and so is the heading error per step."""
    for data in rooms:
        dead = evaluate(run("dead-reckoning", data, seed=0), data).scores
        lo = run("laser-odometry", data, seed=0, config={"reference": reference})
        scores = evaluate(lo, data).scores
        assert scores.ate.rmse < 0.5 * dead.ate.rmse, (scores.ate.rmse, dead.ate.rmse)
        assert scores.rpe_1_step.rotation_rmse < 0.6 * dead.rpe_1_step.rotation_rmse
        d = lo.output.diagnostics
        assert d["matched"] >= 0.95 * d["scans"] and d["keyframes"] >= 50
        assert lo.output.grid is not None  # the keyframes' occupancy map


def _late_odometry(data, steps: list[int], turn_deg: float):
    """``data`` with the wheels' reading wrong for one scan at each of ``steps``: the control
    before it turns ``turn_deg`` more, the next one that much less (as a message delivered
    late and out of order makes a spinning robot's odometry say)."""
    events = list(data.events)
    controls = [i for i, e in enumerate(events) if isinstance(e, Control)]
    for k in steps:
        for i, sign in ((controls[k], 1.0), (controls[k + 1], -1.0)):
            e = events[i]
            u = e.u.copy()
            u[1] += sign * np.deg2rad(turn_deg) / e.dt
            events[i] = dataclasses.replace(e, u=u)
    return dataclasses.replace(data, events=tuple(events))


def test_a_prior_turned_the_wrong_way_is_relocated_by_the_surface_fit(rooms) -> None:
    """Three one-scan odometry errors of 18° on each of the rooms' seeds 0-2: held to that
    prior the match settles 15-18° off the truth; the surface fit sees it, the relocation
    finds the scan's place (5 scans a seed, one of them an override on seed 2) and the
    largest heading error stays that of the clean run (measured: 2.00° against 1.77°,
    1.06° against 1.19°, 0.83° against 0.80°)."""
    for data in rooms:
        bad = _late_odometry(data, [100, 250, 400], 18.0)
        truth = data.truth
        worst = []
        for d in (data, bad):
            lo = run("laser-odometry", d, seed=0)
            at = np.searchsorted(truth.times, lo.times)
            heading = np.abs(wrap_angle(lo.poses[:, 2] - truth.poses[at, 2]))
            worst.append(np.rad2deg(heading.max()))
        diag = lo.output.diagnostics
        assert diag["relocated"] + diag["odometry_overridden"] >= 3 and diag["lost"] == 0, diag
        assert worst[1] < worst[0] + 0.5, worst


def test_the_removed_recovery_settings_are_named_in_the_error() -> None:
    """The heading search's settings went with it (the relocation replaced it); an old
    config file that sets one is told so, not silently obeyed or ignored."""
    for name in ("recovery_fit", "recovery_span_deg", "recovery_step_deg"):
        with pytest.raises(ConfigError, match=rf"{name} \(laser odometry: removed; .*relocat"):
            config_from_mapping(LaserOdometryConfig, {name: 0.5})


def test_scans_without_returns_keep_the_odometry_and_are_counted(rooms) -> None:
    data = rooms[0]
    blind = tuple(
        LaserScan(e.t, np.full_like(e.ranges, data.laser.max_range))
        if isinstance(e, LaserScan)
        else e
        for e in data.events
    )
    blind_data = dataclasses.replace(data, events=blind)
    lo = run("laser-odometry", blind_data, seed=0)
    dead = run("dead-reckoning", blind_data, seed=0)
    np.testing.assert_allclose(lo.poses, dead.poses, atol=1e-9)
    d = lo.output.diagnostics
    assert d["matched"] == 0 and d["keyframes"] == 0
    assert d["unmatched"]["too_few_points"] == d["scans"]


def test_needs_a_laser_and_odometry_and_validates_its_settings() -> None:
    five = load_dataset("five-features", seed=0)
    with pytest.raises(InputError, match="laser"):
        LaserOdometry(five, LaserOdometryConfig(), np.random.default_rng(0))
    with pytest.raises(ConfigError, match="voxel"):
        LaserOdometryConfig(voxel=0.0)
    with pytest.raises(ConfigError, match="reference"):
        config_from_mapping(LaserOdometryConfig, {"reference": "scan"})
    cfg = config_from_mapping(LaserOdometryConfig, {"map": {"resolution": 0.1}})
    assert cfg.map.resolution == 0.1


# Published "scan matching" (Kümmerle et al., Autonomous Robots 2009; DATA.md) [m].
PUBLISHED_SCAN_MATCHING = {"intel-raw": 0.220, "aces-raw": 0.173, "fr079-raw": 0.258}


@pytest.mark.realdata
@pytest.mark.slow
@pytest.mark.parametrize("name", ["intel-raw", "aces-raw", "fr079-raw"])
def test_whole_logs_beat_the_raw_odometry_and_the_published_scan_matcher(data_root, name) -> None:
    """Each raw log whole (Intel 13,631 scans, ACES 7,374, Freiburg 079 4,934), the default
    settings, against all of the benchmark's relations. Measured (2026-12-07, the
    relocation and judge of ``scanmatch.relocate`` and the restart of a refused
    relocation held to the prior): Intel 0.029 ± 0.067 m, 0.35° (without the restart 0.097
    ± 0.291 m: one scan restarted makes the difference); ACES 0.082 ± 0.272 m, 0.4°;
    Freiburg 079 0.033 ± 0.024 m, 0.4°; published scan matching 0.220 / 0.173 / 0.258 m.
    Without any check of the fit Intel scored 0.86 m, with 30 ICP steps Freiburg 079
    0.28 m. Relations of 3 s or less: 1.9 / 3.6 / 2.5 cm (raw odometry 3.3 / 3.3 / 3.8
    cm)."""
    pytest.importorskip("rosbags", reason="the laser extra (rosbags) is not installed")
    from slamkit.eval.relations import relation_errors, select_relations

    bag = f"laser/rosbags/{name.removesuffix('-raw')}.bag"
    if not (data_root / bag).exists():
        pytest.skip(f"{bag} not under {data_root}")
    data = load_dataset(name, data_root=data_root)
    result = run("laser-odometry", data, seed=0)
    rel = data.truth.relations
    every = relation_errors(result.times, result.poses, rel)
    short = relation_errors(result.times, result.poses, select_relations(rel, max_duration=3.0))
    assert every.covered_fraction == 1.0
    assert every.translation_mean < PUBLISHED_SCAN_MATCHING[name], every.translation_mean
    if name == "intel-raw":
        assert result.output.diagnostics["restarted"] >= 1
        assert every.translation_mean < 0.05, every.translation_mean
    assert every.rotation_mean_deg < 1.0, every.rotation_mean_deg
    assert short.translation_mean < 0.05, short.translation_mean
    odometry = run("dead-reckoning", data, seed=0)
    odo = relation_errors(odometry.times, odometry.poses, rel)
    assert every.translation_mean < 0.3 * odo.translation_mean
