"""Config files that round-trip: a run's config.json re-runs it exactly, the [dataset] table
is honoured, ``--set`` overrides one setting, ``config show`` prints readable defaults."""

from __future__ import annotations

import json
import math
import os
import stat
import tomllib
from dataclasses import dataclass

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.app.runconfig import apply_overrides, defaults_toml, read_run_config, resolve_data
from slamkit.cli.main import app
from slamkit.config import Section, config_from_mapping, config_to_dict, describe_settings, setting
from slamkit.errors import ConfigError
from slamkit.localization.mcl.config import MclConfig
from slamkit.pipeline import get_estimator_entry, list_estimators

runner = CliRunner()


def _run(*args: str) -> str:
    res = runner.invoke(app, list(args))
    assert res.exit_code == 0, res.output
    return res.output


@pytest.mark.parametrize(
    ("estimator", "data"),
    [
        ("ekf-slam", "landmark-clutter"),
        ("mcl", "rooms-laser-global"),
        ("fastslam2", "five-features"),
    ],
)
def test_a_runs_config_json_reruns_it_byte_for_byte(tmp_path, estimator, data):
    first, second = tmp_path / "a", tmp_path / "b"
    _run("run", estimator, "--data", data, "--seed", "4", "--out", str(first), "--no-plots")
    # No --data: the data set (a laser world, whose options a landmark world would refuse)
    # and the seed come from the file.
    _run("run", estimator, "--config", str(first / "config.json"), "--out", str(second),
         "--no-plots")  # fmt: skip
    assert (first / "trajectory.tum").read_bytes() == (second / "trajectory.tum").read_bytes()
    assert json.loads((second / "config.json").read_text()) == json.loads(
        (first / "config.json").read_text()
    )


def test_dataset_in_the_config_file_is_honoured_and_a_conflicting_data_is_an_error(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text('[dataset]\nname = "landmark-loop"\nspeed = 2.0\n')
    out = tmp_path / "o"
    _run("run", "dead-reckoning", "--config", str(cfg), "--out", str(out), "--no-plots")
    written = json.loads((out / "config.json").read_text())["dataset"]
    assert written["name"] == "landmark-loop" and written["speed"] == 2.0
    res = runner.invoke(
        app, ["run", "dead-reckoning", "--config", str(cfg), "--data", "five-features",
              "--out", str(tmp_path / "p")],
    )  # fmt: skip
    assert res.exit_code == 1
    assert "conflicts" in res.output and "landmark-loop" in res.output
    assert not (tmp_path / "p").exists()
    # The same name on both sides is no conflict.
    _run("run", "dead-reckoning", "--config", str(cfg), "--data", "landmark-loop", "--out",
         str(tmp_path / "q"), "--no-plots")  # fmt: skip


def test_set_overrides_one_setting_in_sections_and_the_dataset(tmp_path):
    out = tmp_path / "o"
    _run("run", "mcl", "--data", "five-features", "--out", str(out), "--no-plots",
         "--set", "kld.epsilon=0.1", "--set", "n_particles=300", "--set", "dataset.sigma_v=0.2",
         "--set", "seed=7")  # fmt: skip
    config = json.loads((out / "config.json").read_text())
    assert config["estimator"]["kld"]["epsilon"] == 0.1
    assert config["estimator"]["n_particles"] == 300
    assert config["dataset"]["sigma_v"] == 0.2 and config["seed"] == 7
    res = runner.invoke(app, ["run", "mcl", "--set", "kld.nonsense=1", "--out", str(out / "x")])
    assert res.exit_code == 1 and "nonsense" in res.output


def test_overrides_parse_toml_values_and_refuse_malformed_ones():
    cfg = apply_overrides(
        read_run_config(None),
        ["association=jcbb", 'sensor="range"', "laser.offset=[0.1, 0, 0]", "estimator.x=true",
         "dataset.path=my.bag"],
        "estimator",
    )  # fmt: skip
    assert cfg.settings == {"association": "jcbb", "sensor": "range",
                            "laser": {"offset": [0.1, 0, 0]}, "x": True}  # fmt: skip
    assert resolve_data(None, cfg) == "my.bag"
    for bad in ("novalue", "=3", "a..b=1", "seed=x"):
        with pytest.raises(ConfigError):
            apply_overrides(read_run_config(None), [bad], "estimator")


@dataclass(frozen=True)
class _Unbounded(Section):
    """A section with a setting that may be infinite (as some estimators' ranges are)."""

    limit: float = setting(1.0, lambda v: v >= 0, "a number >= 0 or inf")


def test_infinite_settings_round_trip_through_json():
    # config.json writes inf as the string "inf" (JSON has no infinity); it reads back.
    written = json.loads(json.dumps(config_to_dict(_Unbounded(math.inf))))
    assert written == {"limit": "inf"}
    assert config_from_mapping(_Unbounded, written) == _Unbounded(math.inf)
    with pytest.raises(ConfigError, match="limit"):
        config_from_mapping(_Unbounded, {"limit": "many"})


def test_config_show_prints_every_default_with_its_documentation_as_toml():
    text = _run("config", "show", "mcl")
    parsed = tomllib.loads(text)["estimator"]
    docs = describe_settings(MclConfig)
    defaults = config_to_dict(MclConfig())
    # Every setting with a value is in the file, with its default; sections as tables.
    for doc in docs:
        *sections, name = doc.key.split(".")
        table, want = parsed, defaults
        for s in sections:
            table, want = table[s], want[s]
        if doc.default is None:
            assert name not in table and f"# {name} =" in text
        else:
            assert table[name] == want[name], doc.key
    assert "Bound on the Kullback-Leibler divergence" in text  # kld.epsilon's docstring
    # The printed file is a valid config: it runs, to the defaults.
    assert config_from_mapping(MclConfig, parsed) == MclConfig()


def test_every_estimators_defaults_print_and_read_back():
    for entry in list_estimators():
        cls = entry.config_type()
        parsed = tomllib.loads(defaults_toml(cls, "estimator"))["estimator"]
        assert config_from_mapping(cls, parsed) == cls(), entry.name
        assert any(d.doc for d in describe_settings(cls)), entry.name


def test_result_folders_are_readable_by_the_group(tmp_path):
    old = os.umask(0o022)
    try:
        out = tmp_path / "o"
        _run("run", "dead-reckoning", "--out", str(out), "--no-plots")
    finally:
        os.umask(old)
    mode = stat.S_IMODE(out.stat().st_mode)
    assert mode == 0o755


def test_version():
    from importlib.metadata import version

    assert _run("--version").strip() == f"slamkit {version('slamkit')}"


def test_run_without_data_runs_the_default_data_set(tmp_path):
    out = tmp_path / "o"
    _run("run", "dead-reckoning", "--out", str(out), "--no-plots")
    assert json.loads((out / "config.json").read_text())["dataset"]["name"] == "five-features"
    assert np.isfinite(json.loads((out / "metrics.json").read_text())["ate"]["rmse"])


def test_the_readme_sample_config_is_valid_and_asks_for_snapshots(tmp_path):
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    (block,) = re.findall(r"```toml\n(.*?)```", readme, re.S)
    path = tmp_path / "sample.toml"
    path.write_text(block)
    cfg = read_run_config(path)
    assert resolve_data(None, cfg) == "rooms-laser-global" and cfg.seed == 3
    mcl = get_estimator_entry("mcl").make_config(cfg.settings)
    assert mcl.snapshots.every == 25 and mcl.snapshots.times == (0.5, 5.0, 30.0)
    from slamkit.datasets import load_dataset

    assert load_dataset("rooms-laser-global", options=cfg.dataset_options).initial_pose is None


def test_map_occupancy_honours_the_config_files_data_set(tmp_path):
    cfg = tmp_path / "m.toml"
    cfg.write_text('[dataset]\nname = "corridor-loop-laser"\n')
    out = tmp_path / "m"
    _run("map", "occupancy", "--config", str(cfg), "--no-agreement", "--out", str(out))
    written = json.loads((out / "config.json").read_text())
    assert "corridor-loop-laser" in json.dumps(written)
    res = runner.invoke(app, ["map", "occupancy", "--config", str(cfg), "--data", "rooms-laser",
                              "--out", str(tmp_path / "n")])  # fmt: skip
    assert res.exit_code == 1 and "conflicts" in res.output


def test_config_show_with_data_prints_a_file_that_runs_the_defaults(tmp_path):
    text = _run("config", "show", "ekf-slam", "--data", "landmark-clutter")
    parsed = tomllib.loads(text)
    assert parsed["dataset"]["name"] == "landmark-clutter"
    assert parsed["dataset"]["identities"] is False  # the variant's own default
    cfg = tmp_path / "c.toml"
    cfg.write_text(text)
    a, b = tmp_path / "a", tmp_path / "b"
    _run("run", "ekf-slam", "--config", str(cfg), "--out", str(a), "--no-plots")
    _run("run", "ekf-slam", "--data", "landmark-clutter", "--out", str(b), "--no-plots")
    assert (a / "trajectory.tum").read_bytes() == (b / "trajectory.tum").read_bytes()


def test_map_occupancy_takes_set_overrides(tmp_path):
    out = tmp_path / "m"
    _run("map", "occupancy", "--no-agreement", "--out", str(out), "--set", "model.max_range=12",
         "--set", "dataset.sigma_v=0.2")  # fmt: skip
    text = (out / "config.json").read_text()
    assert '"max_range": 12.0' in text and '"sigma_v": 0.2' in text


# ------------------------------------------------------------------------------------------
# a data file's options: the reader chosen for it, documented, and the file runs as printed
# ------------------------------------------------------------------------------------------


def test_config_show_with_a_path_documents_the_chosen_readers_options_and_runs(
    tmp_path, carmen_log
):
    from slamkit.datasets.carmen import CarmenOptions

    log = carmen_log()
    text = _run("config", "show", "dead-reckoning", "--data", str(log))
    parsed = tomllib.loads(text)
    table = parsed["dataset"]
    assert table["path"] == str(log.resolve())
    # The corrected log's reader's options, each under its attribute docstring.
    for doc in describe_settings(CarmenOptions):
        if doc.default is None:
            assert f"# {doc.key} =   (unset)" in text
        else:
            assert table[doc.key] == doc.default
    assert "# Standard deviation of the noise added to each step's translation [m]." in text
    # The reader key: documented with its allowed values, commented out (chosen by content).
    assert "reader" not in table
    assert '# (one of "rosbag", "carmen-raw", "carmen-corrected", "dpslam", "landmark-csv")' in text
    assert '# reader = "carmen-corrected"' in text
    # The printed file runs as it is, as --data FILE does.
    cfg = tmp_path / "c.toml"
    cfg.write_text(text)
    a, b = tmp_path / "a", tmp_path / "b"
    _run("run", "dead-reckoning", "--config", str(cfg), "--out", str(a), "--no-plots")
    _run("run", "dead-reckoning", "--data", str(log), "--out", str(b), "--no-plots")
    assert (a / "trajectory.tum").read_bytes() == (b / "trajectory.tum").read_bytes()
    assert json.loads((a / "config.json").read_text())["dataset"]["path"] == str(log.resolve())


def test_config_show_names_each_readers_options(tmp_path, carmen_log):
    from slamkit.datasets.carmen_raw import CarmenRawOptions
    from slamkit.datasets.landmark_csv import LandmarkCsvOptions

    raw = carmen_log("raw.log", corrected=False)
    csv = tmp_path / "lm.csv"
    csv.write_text("kind,t,a,b,c\ncontrol,0.1,1.0,0.0,0.1\nreading,0.1,2.0,0.1,1\n")
    for path, cls, reader in ((raw, CarmenRawOptions, "carmen-raw"),
                              (csv, LandmarkCsvOptions, "landmark-csv")):  # fmt: skip
        text = _run("config", "show", "dead-reckoning", "--data", str(path))
        table = tomllib.loads(text)["dataset"]
        keys = {d.key for d in describe_settings(cls) if d.default is not None}
        assert keys <= set(table) and f'# reader = "{reader}"' in text, reader
    res = runner.invoke(app, ["config", "show", "dead-reckoning", "--data", "intle"])
    assert res.exit_code == 1 and "intel" in res.output  # a misspelt name lists the names


def test_every_registered_data_set_names_the_class_of_its_options():
    from slamkit.datasets import list_datasets

    for entry in list_datasets():
        cls = entry.options_type()
        assert cls is not None, entry.name
        config_from_mapping(cls, entry.defaults, entry.name)  # its variant's defaults fit
        assert any(d.doc for d in describe_settings(cls)), entry.name
