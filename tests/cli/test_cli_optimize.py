"""``slamkit optimize``: graph files in, the optimised graph, metrics and plots out.

Synthetic graphs written into ``tmp_path`` check exact recovery and the format rules (iSAM in,
g2o out with renumbered landmarks); the public graphs check published and measured optima;
every run checks that the written graph reads back to the reported χ².
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.geometry.angles import wrap_angle
from slamkit.geometry.pose2 import between, inverse_transform_points
from slamkit.io.posegraph import read_graph
from slamkit.optim import g2o_chi2

runner = CliRunner()

PNG = b"\x89PNG\r\n\x1a\n"


def _optimize(src: Path, out: Path, *args: str) -> dict:
    res = runner.invoke(app, ["optimize", str(src), "--out", str(out), *args])
    assert res.exit_code == 0, res.output
    assert "χ² final" in res.output and str(out) in res.output.replace("\n", "")
    metrics = json.loads((out / "metrics.json").read_text())
    assert f"{metrics['chi2_final']:.6g}" in res.output
    return metrics


def _readback(out: Path, metrics: dict):
    """The written graph, read back, and its χ² at its own vertices (and landmarks.csv)."""
    graph = read_graph(out / metrics["output"]["graph_file"])
    landmarks = None
    if metrics["output"]["landmarks_file"]:
        table = np.loadtxt(out / "landmarks.csv", delimiter=",", skiprows=1, ndmin=2)
        ids = table[:, 0].astype(np.int64)
        refs = np.unique(np.concatenate([e.j for e in graph.edges if e.kind == "range_bearing"]))
        np.testing.assert_array_equal(ids, refs)  # rows in the optimiser's landmark order
        landmarks = table[:, 1:]
    return graph, g2o_chi2(graph, graph.poses, landmarks)


def _error_line(res) -> str:
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 1, res.output
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    return lines[0]


# ------------------------------------------------------------------------------ synthetic

_ANGLES = np.arange(6) / 6 * 2 * np.pi
HEXAGON = np.column_stack(
    [2 * np.cos(_ANGLES), 2 * np.sin(_ANGLES), wrap_angle(_ANGLES + np.pi / 2)]
)
INFO = np.array([[100.0, 5.0, 0.0], [5.0, 80.0, 2.0], [0.0, 2.0, 400.0]])
UPPER = (0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)


def _chi2(poses: np.ndarray, edges: list[tuple[int, int]], truth: np.ndarray) -> float:
    """g2o's χ² by hand: e = (x, y, wrapped θ) of Z⁻¹ X_i⁻¹ X_j, Σ eᵀ Ω e."""
    total = 0.0
    for i, j in edges:
        z = between(truth[i], truth[j])
        e = between(z, between(poses[i], poses[j]))
        e[2] = wrap_angle(e[2])
        total += float(e @ INFO @ e)
    return total


def test_synthetic_g2o_loop_recovers_the_true_poses(tmp_path):
    """Six poses on a hexagon with exact measurements (odometry, the loop closure 5→0 and a
    chord 0→3) and vertices perturbed by up to 0.3 m / 0.2 rad (pose 0 exact: the anchor):
    the optimum is the truth with χ² = 0; the reported initial χ² equals a hand computation.
    The chordal relaxation of exact measurements is the truth, so the default start (auto)
    takes it over the file's vertices and records both costs."""
    rng = np.random.default_rng(7)
    start = HEXAGON + np.vstack([np.zeros(3), rng.uniform(-1, 1, (5, 3)) * [0.3, 0.3, 0.2]])
    edges = [(k, (k + 1) % 6) for k in range(6)] + [(0, 3)]
    lines = [f"VERTEX_SE2 {k} {x!r} {y!r} {t!r}" for k, (x, y, t) in enumerate(start.tolist())]
    for i, j in edges:
        z = between(HEXAGON[i], HEXAGON[j]).tolist()
        info = " ".join(repr(float(INFO[a, b])) for a, b in UPPER)
        lines.append(f"EDGE_SE2 {i} {j} {z[0]!r} {z[1]!r} {z[2]!r} {info}")
    src = tmp_path / "hexagon.g2o"
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    m = _optimize(src, out)
    assert sorted(p.name for p in out.iterdir()) == [
        "config.json", "graph.png", "metrics.json", "optimized.g2o",
    ]  # fmt: skip
    assert (out / "graph.png").read_bytes()[:8] == PNG
    hand = _chi2(start, edges, HEXAGON)
    assert m["start"]["costs"]["file"] == pytest.approx(hand, rel=1e-12) and hand > 100.0
    assert m["start"]["costs"]["chordal"] < 1e-18 and m["chi2_initial"] < 1e-18
    assert m["start"]["requested"] == "auto" and m["start"]["used"] == "chordal"
    assert m["start"]["reason"].startswith("chordal: cost")
    assert m["information_repair"]["mode"] == "none" and m["information_repair"]["repaired"] == 0
    assert m["chi2_final"] < 1e-18 and m["converged"]
    assert (m["poses"], m["landmarks"], m["edges"]) == (6, 0, 7)
    assert m["solver"] == "lm" and m["initialization"] == "chordal"
    assert m["linear_solver"] in ("cholmod", "superlu")
    assert m["output"] == {
        "graph_file": "optimized.g2o",
        "family": "g2o",
        "landmarks_file": None,
        "landmark_id_offset": 0,
        "notes": [],
    }
    assert m["solve_seconds"] > 0 and len(m["history"]) == m["iterations"]
    graph, chi2 = _readback(out, m)
    np.testing.assert_allclose(graph.poses, HEXAGON, atol=1e-9)
    assert chi2 == pytest.approx(m["chi2_final"], rel=1e-9, abs=1e-20)
    config = json.loads((out / "config.json").read_text())
    assert config["solver"] == "lm" and config["init"] == "chordal"
    assert config["objective"] == "g2o" and config["robust_kernel"] == "none"
    assert config["optimizer"]["solver"] == "lm"
    assert config["optimizer"]["initialization"] == "chordal"
    assert config["optimizer"]["stopping"]["max_iterations"] == 100
    m = _optimize(src, tmp_path / "from-file", "--init", "file")
    assert m["chi2_initial"] == pytest.approx(hand, rel=1e-12) and m["iterations"] >= 1
    assert m["start"] == {
        "requested": "file", "used": "file", "costs": {},
        "reason": "initialization 'vertices' was asked for",
    }  # fmt: skip
    assert m["chi2_final"] < 1e-18 and m["initialization"] == "file"


def test_synthetic_isam_landmark_graph_is_written_as_g2o_with_renumbered_landmarks(tmp_path):
    """An iSAM file (no vertices; pose ids 0-3 and landmark ids 0-1 share numbers) with exact
    odometry, one loop closure and landmark readings: the default start of a landmark graph
    (grown prefixes) and the optimum are the truth,
    the output is g2o with landmark ids shifted by 4 (largest pose id + 1), and it reads back
    with the same χ² and the true landmarks."""
    truth = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [1.5, 1.0, 1.8], [0.2, 1.2, -2.9]])
    lms = np.array([[3.0, 2.0], [-1.0, 2.5]])
    lines = []
    for i, j in [(0, 1), (1, 2), (2, 3), (3, 0)]:
        z = between(truth[i], truth[j]).tolist()
        lines.append(f"ODOMETRY {i} {j} {z[0]!r} {z[1]!r} {z[2]!r} 10 0 0 10 0 20")
    for p, k in [(0, 0), (1, 0), (1, 1), (2, 1), (3, 1), (3, 0)]:
        x, y = inverse_transform_points(truth[p], lms[k]).tolist()
        lines.append(f"LANDMARK {p} {k} {x!r} {y!r} 5 0 5")
    src = tmp_path / "tiny.txt"
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    m = _optimize(src, out, "--no-plots")
    assert sorted(p.name for p in out.iterdir()) == ["config.json", "metrics.json", "optimized.g2o"]
    assert m["input"]["family"] == "isam" and m["initialization"] == "grow"
    assert (m["poses"], m["landmarks"], m["edges"]) == (4, 2, 10)
    assert m["edges_by_kind"] == {"se2": 4, "se2_xy": 6}
    assert m["chi2_initial"] < 1e-18 and m["chi2_final"] < 1e-18
    assert m["output"]["family"] == "g2o" and m["output"]["landmark_id_offset"] == 4
    assert any("cannot hold vertices" in n for n in m["output"]["notes"])
    assert json.loads((out / "config.json").read_text())["output"]["landmark_id_offset"] == 4
    text = (out / "optimized.g2o").read_text()
    assert "VERTEX_XY 4 " in text and "VERTEX_XY 5 " in text and "EDGE_SE2_XY 3 4 " in text
    graph, chi2 = _readback(out, m)
    np.testing.assert_array_equal(graph.pose_ids, [0, 1, 2, 3])
    np.testing.assert_array_equal(graph.landmark_ids, [4, 5])
    np.testing.assert_allclose(graph.poses, truth, atol=1e-9)
    np.testing.assert_allclose(graph.landmarks, lms, atol=1e-9)
    assert chi2 == pytest.approx(m["chi2_final"], rel=1e-9, abs=1e-20)


def test_malformed_line_is_one_line_naming_file_and_line_and_writes_nothing(tmp_path):
    src = tmp_path / "bad.g2o"
    src.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 x\n")
    res = runner.invoke(app, ["optimize", str(src), "--out", str(tmp_path / "out")])
    assert f"{src}:3:" in _error_line(res)
    assert [p.name for p in tmp_path.iterdir()] == ["bad.g2o"]  # no folder, no partial one


def test_missing_file_and_missing_vertex_are_one_line_errors(tmp_path):
    res = runner.invoke(app, ["optimize", str(tmp_path / "nope.g2o"), "--out", str(tmp_path / "o")])
    assert "nope.g2o: not found" in _error_line(res)
    src = tmp_path / "dangling.g2o"
    src.write_text("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 7 1 0 0 1 0 0 1 0 1\n")
    res = runner.invoke(app, ["optimize", str(src), "--out", str(tmp_path / "o")])
    line = _error_line(res)
    assert "dangling.g2o" in line and ":2" in line and "pose 7" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling.g2o"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--solver", "newton"], "solver: expected one of lm, gn, dogleg, mlr, gauss_seidel"),
        (["--objective", "chordal"], "objective: expected one of g2o, sesync"),
        (["--robust", "tukey"], "robust kernel: expected one of none, huber"),
        (["--robust", "huber", "--robust-width", "-1"], "expected a number > 0"),
        (["--init", "magic"], "init: expected one of auto, file, odometry, chordal, grow"),
        (["--max-iterations", "-3"], "stopping.max_iterations: expected an integer >= 0"),
    ],
)
def test_bad_options_are_one_line_errors(tmp_path, args, message):
    src = tmp_path / "g.g2o"
    src.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n")
    res = runner.invoke(app, ["optimize", str(src), "--out", str(tmp_path / "o"), *args])
    assert message in _error_line(res)
    assert not (tmp_path / "o").exists()


def test_existing_output_folder_needs_overwrite(tmp_path):
    src = tmp_path / "g.g2o"
    src.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1.2 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n")
    out = tmp_path / "o"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    res = runner.invoke(app, ["optimize", str(src), "--out", str(out)])
    assert "use --overwrite" in _error_line(res)
    assert [p.name for p in out.iterdir()] == ["keep.txt"]
    m = _optimize(src, out, "--overwrite", "--no-plots", "--solver", "gn", "--init", "file")
    # One edge, start 0.2 m off: χ² = 0.2² · 1 = 0.04, solved exactly by one GN step.
    assert m["chi2_initial"] == pytest.approx(0.04, rel=1e-12) and m["chi2_final"] < 1e-20
    assert not (out / "keep.txt").exists()


# ------------------------------------------------------------------------------ real data


def _real(data_root: Path, rel: str) -> Path:
    path = data_root / rel
    if not path.exists():
        pytest.skip(f"{path} not found")
    return path


@pytest.mark.realdata
def test_intel_sesync_objective_reaches_the_published_optimum(data_root, tmp_path):
    """SE-Sync's certified optimum of intel.g2o is F* = 5.235e1 (Rosen et al., IJRR 2019);
    measured 52.3483 after 8 LM iterations from the file's vertices (χ² 551.74 → 46.31)."""
    out = tmp_path / "intel"
    m = _optimize(
        _real(data_root, "posegraph2d/intel.g2o"), out, "--objective", "sesync", "--init", "file"
    )
    assert f"{m['sesync_objective_final']:.4g}" == "52.35"
    assert m["cost_final"] == pytest.approx(m["sesync_objective_final"], rel=1e-12)
    assert m["chi2_initial"] == pytest.approx(551.7357, rel=1e-6)
    assert m["chi2_final"] < m["chi2_initial"] / 10 and m["converged"]
    assert (m["poses"], m["landmarks"], m["edges"]) == (1728, 0, 2512)
    costs = [h["cost"] for h in m["history"]]
    assert all(b < a for a, b in zip([m["cost_initial"], *costs], costs, strict=False))
    assert (out / "graph.png").read_bytes()[:8] == PNG
    _, chi2 = _readback(out, m)
    assert chi2 == pytest.approx(m["chi2_final"], rel=1e-12)


@pytest.mark.realdata
@pytest.mark.parametrize("solver", ["gn", "lm", "dogleg", "mlr"])
def test_intel_g2o_objective_is_the_same_for_every_solver(data_root, tmp_path, solver):
    """The g2o χ² minimum of intel.g2o from its vertices: 45.004696 (measured; GN and LM in
    3 iterations, dogleg in 5, MLR in 4 with 16 V-cycles), below the χ² at the SE-Sync
    optimum (46.31)."""
    out = tmp_path / solver
    m = _optimize(_real(data_root, "posegraph2d/intel.g2o"), out, "--solver", solver, "--no-plots")
    assert m["solver"] == solver and m["converged"]
    assert m["chi2_final"] == pytest.approx(45.004696, rel=1e-6)
    _, chi2 = _readback(out, m)
    assert chi2 == pytest.approx(m["chi2_final"], rel=1e-12)


@pytest.mark.realdata
def test_intel_robust_kernel_cost_is_below_its_chi2(data_root, tmp_path):
    """Cauchy with c = 3: ρ(s) = c² log(1 + s/c²) < s, so the reported robust cost (44.75,
    measured) lies below the χ² of the same solution (45.008, within 0.01 % of the plain
    optimum: intel has no gross outliers)."""
    src = _real(data_root, "posegraph2d/intel.g2o")
    m = _optimize(src, tmp_path / "c", "--robust", "cauchy", "--robust-width", "3", "--no-plots")
    assert m["robust_kernel"] == "cauchy"
    assert m["cost_final"] < m["chi2_final"]
    assert m["chi2_final"] == pytest.approx(45.004696, rel=1e-3)
    config = json.loads((tmp_path / "c" / "config.json").read_text())
    assert config["robust_width"] == 3.0 and config["optimizer"]["robust"]["kernel"] == "cauchy"


@pytest.mark.realdata
def test_csail_without_vertices_starts_chordal_and_reaches_f_star(data_root, tmp_path):
    """CSAIL.g2o has no vertices: the default start is chordal, whose F (31.718, measured) is
    already within 0.1 % of F* = 3.170e1; odometry chaining starts at χ² 2.2e6 against the
    chordal 2.0e4, and both reach χ² 40.5551. Minimising F gives F* to 4 digits."""
    src = _real(data_root, "posegraph2d/CSAIL.g2o")
    chordal = _optimize(src, tmp_path / "chordal", "--no-plots")
    odometry = _optimize(src, tmp_path / "odometry", "--init", "odometry", "--no-plots")
    assert chordal["initialization"] == "chordal" and odometry["initialization"] == "odometry"
    assert chordal["sesync_objective_initial"] == pytest.approx(31.70, rel=1e-3)
    assert odometry["chi2_initial"] > 50 * chordal["chi2_initial"] > 50 * 1e4
    for m in (chordal, odometry):
        assert m["chi2_final"] == pytest.approx(40.5551, rel=1e-5) and m["converged"]
    sesync = _optimize(src, tmp_path / "sesync", "--objective", "sesync", "--no-plots")
    assert f"{sesync['sesync_objective_final']:.4g}" == "31.7"
    assert sesync["sesync_objective_final"] == pytest.approx(31.70, abs=0.005)
    graph, chi2 = _readback(tmp_path / "chordal", chordal)
    assert graph.poses.shape == (1045, 3)  # the output has the vertices the input lacked
    assert chi2 == pytest.approx(chordal["chi2_final"], rel=1e-12)


@pytest.mark.realdata
def test_toro_file_is_written_as_toro(data_root, tmp_path):
    """w100.graph (TORO order, EQUIV lines): χ² 17.997 → 1.0362 (measured); the output is
    TORO again, with the equivalences."""
    out = tmp_path / "w100"
    src = _real(data_root, "posegraph2d/w100.graph")
    m = _optimize(src, out, "--no-plots", "--init", "file")
    assert m["output"]["family"] == "toro" and m["output"]["graph_file"] == "optimized.graph"
    assert m["chi2_initial"] == pytest.approx(17.9972, rel=1e-5)
    assert m["chi2_final"] == pytest.approx(1.03618, rel=1e-5)
    graph, chi2 = _readback(out, m)
    assert graph.family == "toro"
    np.testing.assert_array_equal(graph.equivalences, read_graph(src).equivalences)
    assert chi2 == pytest.approx(m["chi2_final"], rel=1e-12)


@pytest.mark.realdata
def test_toro_bearing_range_graph_writes_landmarks_beside_it(data_root, tmp_path):
    """example_gtsam_BR.graph: 95 poses, 24 landmarks seen by BR lines. TORO has no landmark
    vertices, so the landmarks go to landmarks.csv; χ² 4478.1 → 559.05 (measured)."""
    out = tmp_path / "br"
    m = _optimize(_real(data_root, "landmarks/example_gtsam_BR.graph"), out)
    assert (m["poses"], m["landmarks"], m["edges"]) == (95, 24, 516)
    assert m["output"]["landmarks_file"] == "landmarks.csv" and m["output"]["family"] == "toro"
    assert m["chi2_final"] == pytest.approx(559.047, rel=1e-5)
    assert m["chi2_final"] < m["chi2_initial"] / 8
    _, chi2 = _readback(out, m)
    assert chi2 == pytest.approx(m["chi2_final"], rel=1e-12)


@pytest.mark.realdata
def test_isam_city_trees_is_written_as_g2o_with_shifted_landmark_ids(data_root, tmp_path):
    """cityTrees10000.txt (iSAM: 10000 poses, 100 landmarks, ids overlap): written as g2o
    with landmark ids + 10000; χ² 5.04e6 (the default start of a landmark graph: batch
    solves over growing prefixes; chordal poses with landmarks from first readings: 9.03e8)
    → 8668.93 (measured)."""
    out = tmp_path / "city"
    m = _optimize(_real(data_root, "isam/cityTrees10000.txt"), out, "--no-plots")
    assert (m["poses"], m["landmarks"], m["edges"]) == (10000, 100, 14442)
    assert m["output"]["family"] == "g2o" and m["output"]["landmark_id_offset"] == 10000
    assert m["chi2_final"] == pytest.approx(8668.93, rel=1e-5)
    assert m["initialization"] == "grow" and m["chi2_final"] < 2e-3 * m["chi2_initial"]
    graph, chi2 = _readback(out, m)
    assert graph.landmark_ids.min() == 10000 and graph.family == "g2o"
    assert chi2 == pytest.approx(m["chi2_final"], rel=1e-12)


@pytest.mark.realdata
@pytest.mark.parametrize(
    ("name", "init", "chi2_initial", "chi2_final"),
    [
        ("tinyGrid3D.g2o", "file", 213.0644, 6.727882),
        ("smallGrid3D.g2o", "file", 115958.0, 458.1538),
        ("smallGrid3D.g2o", "chordal", 1184.136, 458.1538),
    ],
)
def test_3d_graphs(data_root, tmp_path, name, init, chi2_initial, chi2_final):
    """3D g2o graphs (measured values): the chordal start of smallGrid3D is 100x closer than
    the file's vertices and reaches the same χ²; the plot is the x-y projection."""
    out = tmp_path / "g"
    args = ["--init", init] + ([] if name.startswith("tiny") else ["--no-plots"])
    m = _optimize(_real(data_root, f"posegraph3d/{name}"), out, *args)
    assert m["dim"] == 3 and m["converged"]
    assert m["chi2_initial"] == pytest.approx(chi2_initial, rel=1e-5)
    assert m["chi2_final"] == pytest.approx(chi2_final, rel=1e-5)
    if name.startswith("tiny"):
        assert (out / "graph.png").read_bytes()[:8] == PNG
    graph, chi2 = _readback(out, m)
    assert graph.dim == 3
    assert chi2 == pytest.approx(m["chi2_final"], rel=1e-12)


def test_pose_graph_plot_draws_the_loop_closures_under_the_trajectory():
    """The hexagon's 7 edges: the 5 consecutive ones lie under the trajectory line, the loop
    closure 5→0 and the chord 0→3 are drawn as 2 segments; bad edge rows are an error."""
    from slamkit.errors import InputError
    from slamkit.viz import new_figure, plot_pose_graph

    ax = new_figure().add_subplot()
    edges = np.array([(k, (k + 1) % 6) for k in range(6)] + [(0, 3)])
    drawn = plot_pose_graph(ax, HEXAGON[:, :2], edges=edges, landmarks=np.ones((3, 2)))
    assert len(drawn["edges"].get_segments()) == 2
    np.testing.assert_allclose(drawn["trajectory"].get_xydata(), HEXAGON[:, :2])
    assert drawn["landmarks"].get_offsets().shape == (3, 2)
    with pytest.raises(InputError, match="edges: expected rows in"):
        plot_pose_graph(ax, HEXAGON[:, :2], edges=np.array([[0, 6]]))


@pytest.mark.realdata
def test_victoria_park_graph_reaches_its_optimum_from_the_default_start(data_root, tmp_path):
    """victoriaPark.txt (iSAM: 6969 poses, 151 landmarks, no vertices): the default start of a
    landmark graph (grown prefixes) leads LM to χ² 6184.12 (measured), the optimum
    ``tests/optim/test_optim_landmarks_real.py`` establishes; from the chordal start LM stops far
    above it (measured: not converged in 100 iterations, F 7.2e5)."""
    m = _optimize(_real(data_root, "isam/victoriaPark.txt"), tmp_path / "vp", "--no-plots")
    assert (m["poses"], m["landmarks"]) == (6969, 151)
    assert m["initialization"] == "grow" and m["converged"]
    assert m["chi2_final"] == pytest.approx(6184.12, rel=1e-5)


def test_information_repair_is_an_explicit_option_reported_in_the_metrics(tmp_path):
    """A hexagon whose edges 1 and 4 have [[100, 200], [200, 100]] translation blocks
    (eigenvalue -100): refused naming the first line and the option; with
    ``--repair-information clamp`` both are repaired, counted, listed and warned about."""
    ok, bad = "100 0 0 100 0 1000", "100 200 0 100 0 1000"
    lines = [f"VERTEX_SE2 {k} {x!r} {y!r} {t!r}" for k, (x, y, t) in enumerate(HEXAGON.tolist())]
    edge_line = {}
    for k in range(6):
        z = between(HEXAGON[k], HEXAGON[(k + 1) % 6]).tolist()
        lines.append(
            f"EDGE_SE2 {k} {(k + 1) % 6} {z[0]!r} {z[1]!r} {z[2]!r} {bad if k in (1, 4) else ok}"
        )
        edge_line[k] = len(lines)
    src = tmp_path / "np.g2o"
    src.write_text("\n".join(lines) + "\n")
    res = runner.invoke(app, ["optimize", str(src), "--out", str(tmp_path / "refused")])
    message = _error_line(res)
    assert f"{src}:{edge_line[1]}:" in message and "--repair-information clamp" in message
    assert not (tmp_path / "refused").exists()
    out = tmp_path / "repaired"
    m = _optimize(src, out, "--repair-information", "clamp", "--no-plots")
    repair = m["information_repair"]
    assert repair["mode"] == "clamp" and repair["repaired"] == 2
    assert repair["repaired_by_tag"] == {"EDGE_SE2": 2}
    assert [r["location"] for r in repair["first"]] == [f"{src}:{edge_line[k]}" for k in (1, 4)]
    assert repair["first"][0]["eigenvalue_min"] == pytest.approx(-100.0, rel=1e-12)
    res = runner.invoke(
        app, ["optimize", str(src), "--out", str(out), "--repair-information", "clamp",
              "--overwrite", "--no-plots"],
    )  # fmt: skip
    assert "warning: 2 information matrices were not positive definite" in res.output
    assert m["chi2_final"] < 1e-12 and m["converged"]  # exact measurements: χ² = 0
    config = json.loads((out / "config.json").read_text())
    assert config["repair_information"] == "clamp"


@pytest.mark.parametrize(
    ("solver", "linear", "row"),
    [("mlr", "multigrid", "V-cycles"), ("gauss-seidel", "gauss-seidel", "sweeps")],
)
def test_relaxation_solvers_solve_the_hexagon_without_a_factorisation(
    tmp_path, solver, linear, row
):
    """The hexagon of exact measurements from its perturbed vertices: both relaxation solvers
    reach the truth (χ² from 99.74 to below 1e-14) without factoring, and count their linear
    work."""
    rng = np.random.default_rng(7)
    start = HEXAGON + np.vstack([np.zeros(3), rng.uniform(-1, 1, (5, 3)) * [0.3, 0.3, 0.2]])
    lines = [f"VERTEX_SE2 {k} {x!r} {y!r} {t!r}" for k, (x, y, t) in enumerate(start.tolist())]
    info = " ".join(repr(float(INFO[a, b])) for a, b in UPPER)
    for i, j in [(k, (k + 1) % 6) for k in range(6)]:
        z = between(HEXAGON[i], HEXAGON[j]).tolist()
        lines.append(f"EDGE_SE2 {i} {j} {z[0]!r} {z[1]!r} {z[2]!r} {info}")
    src = tmp_path / "hexagon.g2o"
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / solver
    res = runner.invoke(app, ["optimize", str(src), "--out", str(out), "--solver", solver,
                              "--init", "file", "--no-plots"])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert f"linear {row}" in res.output
    m = json.loads((out / "metrics.json").read_text())
    assert m["solver"] == solver.replace("-", "_") and m["linear_solver"] == linear
    assert m["factorizations"] == 0 and m["linear_iterations"] >= m["iterations"] >= 1
    assert m["chi2_initial"] == pytest.approx(99.7359, rel=1e-5)
    assert m["chi2_final"] < 1e-14 and m["converged"]
    graph, _ = _readback(out, m)
    np.testing.assert_allclose(graph.poses, HEXAGON, atol=1e-8)
