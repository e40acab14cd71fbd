"""Sweep specs, keys, the results table and the report's numbers (no cluster needed)."""

from __future__ import annotations

import math

import pytest

from slamkit.errors import ConfigError
from slamkit.eval import chi2_bounds
from slamkit.sweep import (
    GridAxis,
    RangeAxis,
    best_settings,
    consistency_over_seeds,
    parse_spec,
    read_table,
    run_key,
    run_sweep,
    write_table,
)
from slamkit.sweep.keys import key_payload
from slamkit.sweep.table import flatten_metrics


def _spec(**sweep):
    raw = {"sweep": {"estimators": ["ekf-localization"], "datasets": ["five-features"]}}
    raw["sweep"].update(sweep.pop("sweep", {}))
    raw.update(sweep)
    return raw


def test_grid_times_seeds_times_estimators():
    spec = parse_spec(
        _spec(
            sweep={"estimators": ["ekf-localization", "dead-reckoning"], "seeds": 4},
            estimator={"motion_cov_scale": [0.5, 1.0, 2.0]},
            dataset={"laps": [1, 2]},
        )
    )
    points = spec.points()
    assert len(points) == 2 * 3 * 2 * 4
    assert spec.swept_names == ("estimator.motion_cov_scale", "dataset.laps")
    first = points[0]
    assert (first.estimator, first.seed) == ("ekf-localization", 0)
    assert first.settings == {"motion_cov_scale": 0.5}
    assert first.dataset_options == {"laps": 1}
    assert {p.seed for p in points} == {0, 1, 2, 3}
    combos = {(p.settings["motion_cov_scale"], p.dataset_options["laps"]) for p in points}
    assert len(combos) == 6


def test_random_samples_stay_in_their_ranges_and_repeat_with_the_sample_seed():
    raw = _spec(
        sweep={"samples": 50, "sample_seed": 7},
        estimator={
            "motion_cov_scale": {"low": 0.25, "high": 4.0, "log": True},
            "measurement_cov_scale": {"low": 1, "high": 3, "integer": True},
        },
    )
    spec = parse_spec(raw)
    assert isinstance(spec.estimator_axes[0], RangeAxis)
    points = spec.points()
    assert len(points) == 50
    motion = [p.settings["motion_cov_scale"] for p in points]
    ints = [p.settings["measurement_cov_scale"] for p in points]
    assert all(0.25 <= v <= 4.0 for v in motion)
    assert set(ints) == {1, 2, 3}
    # log-uniform: about half the draws below the geometric middle, 1.0
    assert 15 <= sum(v < 1.0 for v in motion) <= 35
    assert [p.settings for p in parse_spec(raw).points()] == [p.settings for p in points]
    raw["sweep"]["sample_seed"] = 8
    assert [p.settings for p in parse_spec(raw).points()] != [p.settings for p in points]


def test_nested_section_and_values_form():
    spec = parse_spec(_spec(estimator={"motion_cov_scale": {"values": [1.0, 2.0]}}))
    assert spec.estimator_axes == (GridAxis("motion_cov_scale", (1.0, 2.0)),)


@pytest.mark.parametrize(
    ("raw", "named"),
    [
        (_spec(sweep={"estimators": ["no-such-filter"]}), "no-such-filter"),
        (_spec(estimator={"no_such_setting": [1, 2]}), "no_such_setting"),
        (_spec(estimator={"motion_cov_scale": 2.0, "bogus": 1}), "bogus"),
        (_spec(estimator={"motion_cov_scale": []}), "estimator.motion_cov_scale: empty list"),
        (
            _spec(sweep={"samples": 3}, estimator={"motion_cov_scale": {"low": 2, "high": 1}}),
            "estimator.motion_cov_scale: empty range",
        ),
        (_spec(estimator={"motion_cov_scale": {"low": 1, "high": 2}}), "sweep.samples"),
        (_spec(sweep={"seeds": {"start": 0, "count": 0}}), "sweep.seeds.count"),
        (_spec(sweep={"seeds": []}), "sweep.seeds"),
        (_spec(sweep={"datasets": ["no-such-data"]}), "no-such-data"),
        (_spec(sweep={"colour": "red"}), "colour"),
        (_spec(estimator={"motion_cov_scale": [1.0, -1.0]}), "motion_cov_scale"),
    ],
)
def test_bad_specs_are_config_errors_naming_the_key(raw, named, tmp_path):
    with pytest.raises(ConfigError, match=named.replace("(", r"\(")):
        parse_spec(raw)
    out = tmp_path / "never"
    with pytest.raises(ConfigError):
        run_sweep(raw, out)
    assert not out.exists()  # refused before anything started


def test_bad_spec_file_error_names_the_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(
        '[sweep]\nestimators = ["ekf-localization"]\ndatasets = ["five-features"]\n'
        "[estimator]\nwrong_name = [1, 2]\n"
    )
    with pytest.raises(ConfigError, match=r"bad\.toml.*wrong_name"):
        run_sweep(path, tmp_path / "out")


def test_keys_hash_the_resolved_settings_seed_and_data():
    spec = parse_spec(_spec(sweep={"seeds": 2}, estimator={"motion_cov_scale": [1.0, 2.0]}))
    points = spec.points()
    keys = [run_key(p) for p in points]
    assert len(set(keys)) == 4
    assert all(len(k) == 16 and int(k, 16) >= 0 for k in keys)
    # the default value given explicitly is the same run as leaving it out
    default = parse_spec(_spec()).points()[0]
    assert run_key(default) == keys[0]  # motion_cov_scale = 1.0 is the default
    payload = key_payload(points[1])
    assert payload["seed"] == 1
    assert payload["settings"]["motion_cov_scale"] == 1.0
    assert payload["dataset_options"] == {}


def test_table_round_trip(tmp_path):
    metrics = {
        "estimator": "x",
        "seed": 3,
        "ate": {"rmse": 0.5, "count": 10},
        "nees": {"mean": 3.1, "band_95": [0.2, 9.3]},
        "gps": {"skipped": "no GPS"},
        "diagnostics": {"times": list(range(100))},
    }
    flat = flatten_metrics(metrics)
    assert flat == {
        "ate.rmse": 0.5,
        "ate.count": 10,
        "nees.mean": 3.1,
        "nees.band_95.0": 0.2,
        "nees.band_95.1": 9.3,
        "gps.skipped": "no GPS",
    }
    rows = [
        {
            "key": "a",
            "status": "ok",
            "error": None,
            "estimator": "e",
            "dataset": "d",
            "seed": 0,
            "estimator.k": 1.5,
            **flat,
        },
        {
            "key": "b",
            "status": "failed",
            "error": "ConfigError: laps",
            "estimator": "e",
            "dataset": "d",
            "seed": 1,
            "estimator.k": "text",
        },
    ]
    parquet, csv = write_table(tmp_path, rows)
    assert parquet.name == "results.parquet"
    back = read_table(tmp_path)
    assert [r["key"] for r in back] == ["a", "b"]
    assert back[0]["ate.rmse"] == 0.5
    assert back[1]["ate.rmse"] is None
    assert back[1]["error"] == "ConfigError: laps"
    assert back[0]["estimator.k"] == "1.5"  # a mixed column is kept as text
    assert csv.read_text().splitlines()[0].startswith('"key","status","error"')


def _rows(values, setting=1.0, metric=None):
    return [
        {
            "key": f"{setting}-{i}",
            "status": "ok",
            "estimator": "e",
            "dataset": "d",
            "seed": i,
            "estimator.k": setting,
            "nees.mean": v,
            "nees.dof": 3,
            "nis.count": 100,
            "nis.mean_nis_per_dof": 1.0 + 0.01 * i,
            "ate.rmse": (metric or v) + 0.01 * i,
        }
        for i, v in enumerate(values)
    ]


def test_consistency_over_seeds_numbers():
    rows = _rows([2.0, 3.0, 4.0, 5.0])
    (c,) = consistency_over_seeds(rows, ["estimator.k"])
    assert c.runs == 4
    assert c.nees_mean == pytest.approx(3.5)
    assert c.nees_std == pytest.approx(math.sqrt(5 / 3))
    assert c.nees_band == chi2_bounds(3, 4)
    assert c.nees_inside
    assert c.nis_updates == 400
    assert c.nis_per_dof == pytest.approx(1.015)
    assert c.nis_band == chi2_bounds(1, 400)


def test_best_settings_picks_the_lowest_mean_of_complete_configurations():
    rows = _rows([3, 3], 1.0, metric=0.5) + _rows([3, 3], 2.0, metric=0.2)
    rows += _rows([3, 3], 3.0, metric=0.1)
    rows[-1] = {**rows[-1], "status": "failed", "ate.rmse": None}
    (best,) = best_settings(rows, ["estimator.k"])
    assert best.settings == {"estimator.k": 2.0}
    assert best.mean == pytest.approx(0.205)
    assert (best.runs_ok, best.runs, best.candidates) == (2, 2, 3)
    assert best.metric == "ate.rmse"


def test_the_sweep_package_imports_neither_matplotlib_nor_dask():
    import subprocess
    import sys

    code = (
        "import sys, slamkit.sweep, slamkit.sweep.report, slamkit.sweep.execute\n"
        "print(sorted(m for m in ('matplotlib', 'distributed', 'pyarrow') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_a_file_is_a_data_set_by_its_path_and_its_readers_options_are_checked(
    tmp_path, carmen_log, monkeypatch
):
    carmen_log("run.log")
    monkeypatch.chdir(tmp_path)
    raw = _spec(
        sweep={"estimators": ["dead-reckoning"], "datasets": ["run.log"]},
        dataset={"odometry_sigma_trans": [0.02, 0.05]},
    )
    spec = parse_spec(raw)
    # A relative path is the file in the current folder, named absolutely from then on.
    assert spec.datasets == (str((tmp_path / "run.log").resolve()),)
    assert [p.dataset_options for p in spec.points()] == [
        {"odometry_sigma_trans": 0.02},
        {"odometry_sigma_trans": 0.05},
    ]
    # The [dataset] options go to every data set: five-features (a simulated world) has no
    # odometry noise of a log's reader.
    raw["sweep"]["datasets"] = ["run.log", "five-features"]
    with pytest.raises(ConfigError, match=r"\[dataset\] for five-features: unknown option"):
        parse_spec(raw)
    with pytest.raises(ConfigError, match=r"run\.log: unknown option\(s\) scan_topic; known: "):
        parse_spec(_spec(sweep={"datasets": ["run.log"]}, dataset={"scan_topic": "/scan"}))
    # A named reader's options: the raw reader has `laser`, the corrected one has not.
    named = _spec(
        sweep={"datasets": ["run.log"]}, dataset={"reader": "carmen-raw", "laser": "FLASER"}
    )
    assert parse_spec(named).dataset_fixed == {"reader": "carmen-raw", "laser": "FLASER"}
    with pytest.raises(ConfigError, match="laser"):
        parse_spec(_spec(sweep={"datasets": ["run.log"]}, dataset={"laser": "FLASER"}))
