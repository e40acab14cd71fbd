"""``repair_information="clamp"``: information matrices that are not positive definite are
refused by default (file and line, the option named), repaired on request by eigenvalue
clamping, counted and listed, and never repaired silently."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from slamkit.errors import DatasetFormatError
from slamkit.io.posegraph import RepairWarning, read_graph, read_graph_report
from slamkit.optim import OptimizerConfig, optimize
from slamkit.optim.repair import REPAIR_RTOL, clamp_information

_IU = np.triu_indices(6)


def _pd(rng: np.random.Generator) -> np.ndarray:
    A = rng.normal(size=(6, 6))
    return A @ A.T + 6.0 * np.eye(6)


def _write_3d(path: Path, infos: list[np.ndarray]) -> list[int]:
    """A ring of ``len(infos)`` poses 1 m apart along x (identity rotations), closed by the
    last edge; edge ``k`` carries ``infos[k]``. Returns the edges' line numbers."""
    n = len(infos)
    lines = [f"VERTEX_SE3:QUAT {k} {float(k)!r} 0 0 0 0 0 1" for k in range(n)]
    edge_lines = []
    for k, info in enumerate(infos):
        i, j = k, (k + 1) % n
        dx = 1.0 if j else -(n - 1.0)
        upper = " ".join(repr(float(v)) for v in info[_IU])
        lines.append(f"EDGE_SE3:QUAT {i} {j} {dx!r} 0 0 0 0 0 1 {upper}")
        edge_lines.append(len(lines))
    path.write_text("\n".join(lines) + "\n")
    return edge_lines


def _graph_with_bad_edges(tmp_path: Path) -> tuple[Path, list[np.ndarray], list[int], list[int]]:
    """Eight edges; edge 2 has a negative eigenvalue (an off-diagonal too large), edge 5 a
    zero row and column (rank 5), edge 6 a tiny negative diagonal entry."""
    rng = np.random.default_rng(4)
    infos = [_pd(rng) for _ in range(8)]
    infos[2][0, 1] = infos[2][1, 0] = 1.5 * np.sqrt(infos[2][0, 0] * infos[2][1, 1])
    infos[5][3, :] = 0.0
    infos[5][:, 3] = 0.0
    infos[6][5, 5] = -1e-3
    infos[6][5, :5] = infos[6][:5, 5] = 0.0
    path = tmp_path / "bad.g2o"
    lines = _write_3d(path, infos)
    return path, infos, lines, [2, 5, 6]


def test_not_positive_definite_is_refused_by_default_naming_the_option(tmp_path) -> None:
    path, _, lines, bad = _graph_with_bad_edges(tmp_path)
    with pytest.raises(DatasetFormatError) as info:
        read_graph(path)
    message = str(info.value)
    assert message.startswith(f"{path}:{lines[bad[0]]}: EDGE_SE3:QUAT")
    assert "not positive definite" in message
    assert "repair_information='clamp'" in message and "--repair-information clamp" in message


def test_clamp_repairs_exactly_the_bad_edges_and_keeps_the_others(tmp_path) -> None:
    path, infos, lines, bad = _graph_with_bad_edges(tmp_path)
    with pytest.warns(RepairWarning, match=r"^3 information matrices were not positive") as w:
        report = read_graph_report(path, repair_information="clamp")
    assert f"{path}:{lines[2]}" in str(w[0].message)
    assert [r.line for r in report.repaired] == [lines[k] for k in bad]
    assert {r.tag for r in report.repaired} == {"EDGE_SE3:QUAT"}
    (es,) = report.graph.edges
    for k, original in enumerate(infos):
        lam, V = np.linalg.eigh(original)
        if k not in bad:  # positive definite: the file's matrix, bit for bit
            np.testing.assert_array_equal(es.information[k], original)
            continue
        record = report.repaired[bad.index(k)]
        assert record.eigenvalue_min == pytest.approx(lam[0], rel=1e-9, abs=1e-9)
        assert record.eigenvalue_max == pytest.approx(lam[-1], rel=1e-12)
        repaired = es.information[k]
        np.linalg.cholesky(repaired)  # positive definite now
        floor = REPAIR_RTOL * lam[-1]
        # Ω' = Ω + Σ over the clamped eigenpairs of (floor - λ) v vᵀ: the other eigenpairs stay.
        low = lam < floor
        assert 1 <= low.sum() <= 2
        expected = original + (V[:, low] * (floor - lam[low])) @ V[:, low].T
        np.testing.assert_allclose(repaired, expected, rtol=0, atol=1e-9 * lam[-1])
        new = np.linalg.eigvalsh(repaired)
        assert new[0] == pytest.approx(floor, rel=1e-6)
        np.testing.assert_allclose(new[low.sum() :], lam[low.sum() :], rtol=1e-9)
    # The repaired graph is one the optimiser takes.
    res = optimize(report.graph, OptimizerConfig())
    assert res.converged and np.isfinite(res.chi2)


def test_clamping_is_the_nearest_matrix_with_eigenvalues_above_the_floor() -> None:
    """In the Frobenius norm no matrix with eigenvalues ≥ floor is nearer the original than
    the clamped one: checked against 2000 random such matrices near it."""
    rng = np.random.default_rng(9)
    A = rng.normal(size=(3, 3))
    omega = A + A.T  # indefinite
    clamped = clamp_information(omega[None], np.array([0]))[0]
    floor = REPAIR_RTOL * np.linalg.eigvalsh(omega)[-1]
    best = np.linalg.norm(clamped - omega)
    for _ in range(2000):
        B = clamped + 0.3 * rng.normal(size=(3, 3))
        B = 0.5 * (B + B.T)
        if np.linalg.eigvalsh(B)[0] >= floor:
            assert np.linalg.norm(B - omega) >= best - 1e-12


def test_a_matrix_without_positive_eigenvalues_is_not_repaired(tmp_path) -> None:
    rng = np.random.default_rng(5)
    infos = [_pd(rng) for _ in range(4)]
    infos[1] = -np.eye(6)
    path = tmp_path / "hopeless.g2o"
    lines = _write_3d(path, infos)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing was repaired, so no warning either
        with pytest.raises(DatasetFormatError, match=r"no positive eigenvalue") as info:
            read_graph(path, repair_information="clamp")
    assert str(info.value).startswith(f"{path}:{lines[1]}:")


def test_a_clean_file_reads_the_same_with_the_option(tmp_path) -> None:
    rng = np.random.default_rng(6)
    path = tmp_path / "clean.g2o"
    _write_3d(path, [_pd(rng) for _ in range(5)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report = read_graph_report(path, repair_information="clamp")
    assert report.repaired == ()
    np.testing.assert_array_equal(
        report.graph.edges[0].information, read_graph(path).edges[0].information
    )
