"""Runner, registry, evaluation, config and result files."""

from __future__ import annotations

import itertools
import json
import os
from dataclasses import dataclass

import numpy as np
import pytest

from slamkit.config import config_from_mapping, config_to_dict, load_config_file
from slamkit.datasets import (
    DATASETS,
    Dataset,
    GroundTruth,
    LandmarkReadings,
    LandmarkSensorSpec,
    data_root,
    get_dataset_entry,
    load_dataset,
)
from slamkit.errors import (
    ConfigError,
    ConvergenceError,
    CovarianceError,
    DataNotFoundError,
    DatasetFormatError,
    InputError,
    NonFiniteError,
    ShapeError,
    UnknownNameError,
)
from slamkit.io import atomic_folder, read_tum, write_tum
from slamkit.pipeline import ESTIMATORS, EstimatorEntry, PoseEstimate, run
from slamkit.pipeline.evaluate import evaluate


def test_runner_records_one_pose_per_time_stamp_and_reports_progress():
    ds = load_dataset("five-features", seed=0)
    calls = []
    res = run("dead-reckoning", ds, progress=lambda d, t: calls.append((d, t)))
    assert res.poses.shape == (ds.truth.poses.shape[0], 3)
    assert res.covariances.shape == (ds.truth.poses.shape[0], 3, 3)
    assert calls[-1] == (len(ds), len(ds)) and 50 <= len(calls) <= 102
    assert all(a[0] <= b[0] for a, b in itertools.pairwise(calls))
    assert res.step_seconds.shape == res.times.shape and np.all(res.step_seconds >= 0)
    assert res.config == {"motion_cov_scale": 1.0}


def test_evaluate_dead_reckoning_against_truth():
    ds = load_dataset(
        "five-features",
        seed=0,
        options={
            "sigma_v": 0.0,
            "sigma_omega_deg": 0.0,
            "initial_sigma_xy": 0.0,
            "initial_sigma_theta_deg": 0.0,
        },
    )
    res = run("dead-reckoning", ds)
    m = evaluate(res, ds).metrics
    # Noise-free controls and a known start: dead reckoning is exact.
    assert m["ate_unaligned"]["rmse"] < 1e-9
    assert m["matched_steps"] == ds.truth.poses.shape[0]
    ds_noisy = load_dataset("five-features", seed=0)
    m2 = evaluate(run("dead-reckoning", ds_noisy), ds_noisy).metrics
    assert m2["ate_unaligned"]["rmse"] > 0.05
    assert m2["ate"]["rmse"] <= m2["ate_unaligned"]["rmse"] + 1e-12
    assert 0 < m2["nees"]["mean"] < 30
    json.dumps(m2, allow_nan=False)


def test_run_uses_the_callers_config_only():
    """The runner builds the estimator from the caller's config and nothing else (presets
    are the app layer's); a config object is taken as it is."""
    from slamkit.slam import FastSlamConfig

    ds = load_dataset("five-features", seed=0)
    r = run("fastslam1", ds, config={"n_particles": 9})
    assert r.config["n_particles"] == 9 and r.config["hit_weight"] == 1
    r = run("fastslam1", ds, config=FastSlamConfig(n_particles=5))
    assert r.config["n_particles"] == 5
    with pytest.raises(ConfigError, match="fastslam1"):
        run("fastslam1", ds, config={"x": 1})


def test_registries_resolve_and_reject_unknown_names():
    for entry in ESTIMATORS.values():
        assert entry.config_type() is not None
    for entry in DATASETS.values():
        assert callable(entry.loader())
    with pytest.raises(UnknownNameError, match="known: dead-reckoning"):
        run("nope", load_dataset("five-features"))
    with pytest.raises(UnknownNameError, match="five-features"):
        get_dataset_entry("nope")


def test_missing_real_data_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setenv("SLAMKIT_DATA", str(tmp_path / "missing"))
    with pytest.raises(DataNotFoundError, match="SLAMKIT_DATA"):
        data_root()


class _Exploding:
    def __init__(self, dataset, config, rng):
        self.n = 0

    def handle(self, event):
        self.n += 1

    def estimate(self):
        return PoseEstimate(np.array([0.0, 0.0, np.nan if self.n > 3 else 0.0]))

    def finish(self):
        raise AssertionError("not reached")


def test_a_diverging_estimator_is_reported_with_its_step(monkeypatch):
    import sys
    import types

    mod = types.ModuleType("_slamkit_test_exploding")
    mod.Exploding = _Exploding
    mod.Config = _Cfg
    monkeypatch.setitem(sys.modules, mod.__name__, mod)
    entry = EstimatorEntry("x", "", f"{mod.__name__}:Exploding", f"{mod.__name__}:Config")
    with pytest.raises(ConvergenceError, match="step 3"):  # 1 + 2 + 2 events
        run(entry, load_dataset("five-features"))


@dataclass(frozen=True)
class _Cfg:
    gain: float = 1.0
    mode: str = "a"
    sizes: tuple[int, ...] = (1, 2)
    flag: bool = False


def test_config_from_mapping_validates_keys_and_types(tmp_path):
    cfg = config_from_mapping(_Cfg, {"gain": 2, "sizes": [3, 4], "flag": True})
    assert cfg == _Cfg(2.0, "a", (3, 4), True)
    assert config_to_dict(cfg) == {"gain": 2.0, "mode": "a", "sizes": [3, 4], "flag": True}
    with pytest.raises(ConfigError, match="unknown setting"):
        config_from_mapping(_Cfg, {"gian": 1})
    with pytest.raises(ConfigError, match="expected a number"):
        config_from_mapping(_Cfg, {"gain": "fast"})
    with pytest.raises(ConfigError, match="true or false"):
        config_from_mapping(_Cfg, {"flag": 1})
    p = tmp_path / "c.toml"
    p.write_text("[estimator]\nmotion_cov_scale = 2.0\n")
    assert load_config_file(p) == {"estimator": {"motion_cov_scale": 2.0}}
    p.write_text("[estimator\n")
    with pytest.raises(ConfigError, match="not valid"):
        load_config_file(p)


def test_tum_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    t = np.arange(20) * 0.1
    poses = np.column_stack([rng.normal(size=(20, 2)), rng.uniform(-np.pi, np.pi, 20)])
    write_tum(tmp_path / "a.tum", t, poses)
    t2, p2 = read_tum(tmp_path / "a.tum")
    np.testing.assert_allclose(t2, t, atol=1e-9)
    np.testing.assert_allclose(p2, poses, atol=1e-7)
    first = (tmp_path / "a.tum").read_text().splitlines()[1].split()
    assert len(first) == 8 and float(first[3]) == 0.0
    (tmp_path / "b.tum").write_text("0 1 2 3\n")
    with pytest.raises(DatasetFormatError, match=r"b.tum:1: expected 8 numbers"):
        read_tum(tmp_path / "b.tum")


def test_atomic_folder_leaves_nothing_on_error_and_refuses_to_clobber(tmp_path):
    target = tmp_path / "out"
    with pytest.raises(RuntimeError), atomic_folder(target) as tmp:
        (tmp / "half.json").write_text("{")
        raise RuntimeError("boom")
    assert not target.exists() and os.listdir(tmp_path) == []
    with atomic_folder(target) as tmp:
        (tmp / "a.txt").write_text("1")
    assert (target / "a.txt").read_text() == "1"
    with pytest.raises(InputError, match="not empty"), atomic_folder(target):
        pass
    with atomic_folder(target, overwrite=True) as tmp:
        (tmp / "b.txt").write_text("2")
    assert sorted(os.listdir(target)) == ["b.txt"]
    assert sorted(os.listdir(tmp_path)) == ["out"]


def test_dataset_validation_names_the_bad_event():
    spec = LandmarkSensorSpec("range-bearing", np.diag([0.01, 0.001]))
    good = LandmarkReadings(0.0, np.array([[1.0, 0.1]]), np.array([0]))
    Dataset("ok", (good,), landmark_sensor=spec)
    with pytest.raises(ShapeError, match="event 1"):
        Dataset(
            "bad",
            (good, LandmarkReadings(1.0, np.ones((1, 3)), np.array([0]))),
            landmark_sensor=spec,
        )
    with pytest.raises(NonFiniteError):
        Dataset(
            "bad",
            (LandmarkReadings(0.0, np.array([[np.nan, 0.1]]), np.array([0])),),
            landmark_sensor=spec,
        )
    with pytest.raises(InputError, match="non-decreasing"):
        Dataset("bad", (LandmarkReadings(1.0, good.z, good.ids), good), landmark_sensor=spec)
    with pytest.raises(CovarianceError):
        LandmarkSensorSpec("range-bearing", np.diag([0.01, -0.001]))
    with pytest.raises(InputError, match="times and poses"):
        GroundTruth(times=np.zeros(3))


def test_metrics_that_do_not_apply_are_skipped_with_a_reason():
    # A short run (2 s at 1 m/s) cannot give a 10 m relative pose error: the metric says why.
    ds = load_dataset("five-features", seed=0)
    short = Dataset(
        ds.name,
        tuple(e for e in ds.events if e.t <= 2.0),
        motion=ds.motion,
        landmark_sensor=ds.landmark_sensor,
        initial_pose=ds.initial_pose,
        initial_cov=ds.initial_cov,
        truth=GroundTruth(ds.truth.times[:21], ds.truth.poses[:21], ds.truth.landmarks),
    )
    m = evaluate(run("dead-reckoning", short), short).metrics
    assert "skipped" in m["rpe_10_m"] and "rmse" in m["ate"]


def test_a_renamed_setting_is_named_with_its_replacement():
    """Noise scaling has one meaning, a factor on the covariance (``*_cov_scale``); a config
    with the old names is refused with what to write instead."""
    ds = load_dataset("five-features", seed=0)
    with pytest.raises(ConfigError, match=r"measurement_cov_scale.*square the old value"):
        run("fastslam1", ds, config={"measurement_noise_scale": 6.0})
    # FastSLAM's reading covariance is the sensor's times the factor
    a = run("fastslam1", ds, config={"measurement_cov_scale": 4.0, "n_particles": 20})
    assert a.config["measurement_cov_scale"] == 4.0
