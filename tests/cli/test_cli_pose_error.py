"""``slamkit eval ape|rpe`` on a run's own files: the numbers agree with the run's metrics."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app

runner = CliRunner()


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "ekf"
    res = runner.invoke(app, ["run", "ekf-slam", "--data", "five-features", "--seed", "1",
                              "--out", str(out), "--no-plots", "--format", "kitti"])  # fmt: skip
    assert res.exit_code == 0, res.output
    return out


def test_ape_se2_equals_the_runs_aligned_ate(run_dir, tmp_path):
    out = tmp_path / "ape"
    res = runner.invoke(app, ["eval", "ape", str(run_dir / "groundtruth.tum"),
                              str(run_dir / "trajectory.tum"), "--align", "se2",
                              "--out", str(out)])  # fmt: skip
    assert res.exit_code == 0, res.output
    got = json.loads((out / "metrics.json").read_text())
    run = json.loads((run_dir / "metrics.json").read_text())
    assert got["ape_translation_m"]["rmse"] == pytest.approx(run["ate"]["rmse"], rel=1e-6)
    assert got["matched"] == got["estimate_poses"]
    assert sorted(p.name for p in out.iterdir()) == ["ape.png", "metrics.json", "trajectories.png"]
    # Unaligned, the error is the run's unaligned ATE.
    res = runner.invoke(app, ["eval", "ape", str(run_dir / "groundtruth.tum"),
                              str(run_dir / "trajectory.tum"), "--align", "none", "--no-plots",
                              "--out", str(tmp_path / "raw")])  # fmt: skip
    raw = json.loads((tmp_path / "raw" / "metrics.json").read_text())
    assert raw["ape_translation_m"]["rmse"] == pytest.approx(run["ate_unaligned"]["rmse"], rel=1e-6)


def test_eval_prints_unaligned_numbers_and_writes_nothing_without_out(
    run_dir, tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    files = [str(run_dir / "groundtruth.tum"), str(run_dir / "trajectory.tum")]
    for _ in range(2):  # twice in a row, as evo: nothing to collide with
        res = runner.invoke(app, ["eval", "ape", *files], env={"COLUMNS": "200"})
        assert res.exit_code == 0, res.output
        assert "not aligned" in res.output and "wrote" not in res.output
    assert list(tmp_path.iterdir()) == []
    run = json.loads((run_dir / "metrics.json").read_text())
    rmse = next(line for line in res.output.splitlines() if " rmse " in line).split("│")[2]
    assert float(rmse) == pytest.approx(run["ate_unaligned"]["rmse"], abs=1e-6)


@pytest.mark.parametrize("flags", [[], ["-a"], ["-s"], ["-as"]])
def test_eval_with_evos_flags_equals_evo_with_the_same_flags(run_dir, tmp_path, flags):
    pytest.importorskip("evo", reason="evo is an optional peer: pip install 'slamkit[evo]'")
    from evo.core import metrics, sync
    from evo.main_ape import ape
    from evo.main_rpe import rpe
    from evo.tools import file_interface

    ref_path, est_path = run_dir / "groundtruth.tum", run_dir / "trajectory.tum"
    got = {}
    for kind in ("ape", "rpe"):
        res = runner.invoke(app, ["eval", kind, str(ref_path), str(est_path), *flags,
                                  "--out", str(tmp_path / kind), "--no-plots"])  # fmt: skip
        assert res.exit_code == 0, res.output
        got[kind] = json.loads((tmp_path / kind / "metrics.json").read_text())
    align, scale = "-a" in flags or "-as" in flags, "-s" in flags or "-as" in flags
    theirs = {}
    for kind, metric in (("ape", ape), ("rpe", rpe)):
        ref = file_interface.read_tum_trajectory_file(str(ref_path))
        est = file_interface.read_tum_trajectory_file(str(est_path))  # evo aligns in place
        ref, est = sync.associate_trajectories(ref, est, max_diff=0.01)  # evo's default
        extra = {} if kind == "ape" else {"delta": 1, "delta_unit": metrics.Unit.frames}
        theirs[kind] = metric(ref, est, metrics.PoseRelation.translation_part, align=align,
                              correct_scale=scale, **extra).stats  # fmt: skip
    for kind in ("ape", "rpe"):
        ours = got[kind][f"{kind}_translation_m"]
        for key in ("rmse", "mean", "median", "std", "min", "max", "sse"):
            assert ours[key] == pytest.approx(theirs[kind][key], rel=1e-9, abs=1e-12), (kind, key)


@pytest.mark.parametrize(
    ("flags", "name"),
    [(["-a"], "se3"), (["-s"], "scale"), (["-as"], "sim3"), (["-a", "-s"], "sim3")],
)
def test_evos_short_flags_name_the_alignments(run_dir, tmp_path, flags, name):
    files = [str(run_dir / "groundtruth.tum"), str(run_dir / "trajectory.tum")]
    out = {}
    for label, args in (("flags", flags), ("name", ["--align", name])):
        res = runner.invoke(app, ["eval", "ape", *files, *args, "--no-plots",
                                  "--out", str(tmp_path / label)])  # fmt: skip
        assert res.exit_code == 0, res.output
        out[label] = json.loads((tmp_path / label / "metrics.json").read_text())
    assert out["flags"] == out["name"] and out["flags"]["alignment"] == name
    res = runner.invoke(app, ["eval", "ape", *files, "--align", "se2", *flags])
    assert res.exit_code == 1 and "give one of them" in res.output


def test_rpe_on_kitti_files_pairs_by_index(run_dir, tmp_path):
    kitti = run_dir / "trajectory.kitti"
    res = runner.invoke(app, ["eval", "rpe", str(kitti), str(kitti), "--delta", "5",
                              "--out", str(tmp_path / "r")])  # fmt: skip
    assert res.exit_code == 0, res.output
    got = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert got["rpe_translation_m"]["max"] < 1e-9 and got["rpe_delta"] == 5


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["missing.tum", "missing.tum"], "not found"),
        (["--align", "affine"], "alignment"),
        (["--offset", "1000"], "no matching time stamps"),
    ],
)
def test_bad_input_is_one_line(run_dir, tmp_path, args, message):
    files = [str(run_dir / "groundtruth.tum"), str(run_dir / "trajectory.tum")]
    argv = ["eval", "ape", *(args if args[0].endswith(".tum") else files + args)]
    res = runner.invoke(app, [*argv, "--out", str(tmp_path / "x")])
    assert res.exit_code == 1 and message in res.output, res.output
    assert not (tmp_path / "x").exists()
