"""The Riemannian staircase (``slamkit.optim.riemannian_staircase``): time to a certified
global optimum of SE-Sync's objective ``F`` from bad starts, ranks climbed, and ``F`` reached
against the published ``F*`` (Rosen et al., IJRR 2019).

Cases, each in one run:

* the generated 16-pose ring of ``tests/optim/test_staircase.py`` from LM's local minimum
  reached from one extra turn of heading (the solution the certificate refuses);
* every shared graph with a published ``F*`` (2D: intel, CSAIL, manhattan, city10000;
  3D: sphere2500, parking-garage, torus3D) from uniformly random rotations (seed 0,
  translations zero): the staircase from there, against LM (``objective="sesync"``, at most
  100 iterations) from the *same* rotations and then ``certify``;
* MIT and torus3D from where LM (``objective="sesync"``, 100 iterations) stops from the
  file's vertices, uncertified (what ``slamkit optimize --init file --certify --staircase``
  meets; LM's own time is not in the staircase's);
* Carlone's INTEL from its file's vertices (the hard start of ``docs/estimators/optim.md``'s
  MLR section): the staircase from the vertices against LM from the vertices + ``certify``.

Peer in the same run: LM + ``certify`` from the same start (the "refused" case runs the
staircase after that). A second reference row per graph, LM from the chordal start +
``certify``, is the way slamkit reaches the certified optimum without the staircase.
SE-Sync itself (C++/MATLAB) does not run here; its published timings are not quoted (the
paper's tables could not be consulted from this machine), so no comparison with it is made.

Timed: the whole call (matrices, ``‖Q‖``, factorisations, trust region at every rank,
eigenvalue searches, rounding, the final certificate); one run per cell (the machine is
shared; load averages in the notes).

Run: ``python benchmarks/bench_staircase.py`` or ``python benchmarks/run.py staircase``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

from _common import Record, write_results
from slamkit.datasets import find_data_root
from slamkit.geometry import pose2
from slamkit.io.posegraph import read_graph
from slamkit.optim import (
    EdgeSet,
    GraphData,
    GraphProblem,
    OptimizerConfig,
    StoppingConfig,
    certify,
    optimize,
    riemannian_staircase,
)

F_STAR = {
    "posegraph2d/intel": 5.235e1,
    "posegraph2d/CSAIL": 3.170e1,
    "posegraph2d/manhattan": 6.432e3,
    "posegraph2d/city10000": 6.386e2,
    "posegraph3d/sphere2500": 1.687e3,
    "posegraph3d/parking-garage": 1.263e0,
    "posegraph3d/torus3D": 2.423e4,
}
LM_ITERATIONS = 100


def ring() -> tuple[GraphData, np.ndarray]:
    """The 16-pose ring (noise σ = 0.05 m, 0.05 m, 0.01 rad; seed 12345, as the tests'
    fixture) and its winding start (pose k turned by 2πk/16)."""
    rng = np.random.default_rng(12345)
    n = 16
    a = 2 * np.pi * np.arange(n) / n
    truth = np.column_stack([10 * np.cos(a), 10 * np.sin(a), a + np.pi / 2])
    pairs = [(k, (k + 1) % n) for k in range(n)] + [(k, k + n // 2) for k in range(0, n // 2, 4)]
    i, j = np.array(pairs).T
    sigma = np.array([0.05, 0.05, 0.01])
    z = pose2.between(truth[i], truth[j]) + rng.normal(size=(len(pairs), 3)) * sigma
    info = np.broadcast_to(np.diag(1.0 / sigma**2), (len(pairs), 3, 3)).copy()
    edges = EdgeSet("se2", i, j, z, info, np.zeros(len(pairs), dtype=np.int64))
    graph = GraphData(dim=2, pose_ids=np.arange(n), poses=truth, edges=(edges,))
    start = truth.copy()
    start[:, 2] += a
    return graph, start


def random_rotations(graph: GraphData, seed: int = 0) -> np.ndarray:
    """Zero translations and uniformly random rotations (2D headings, 3D unit quaternions)."""
    n = GraphProblem.from_data(graph, objective="sesync").pose_ids.shape[0]
    rng = np.random.default_rng(seed)
    if graph.dim == 2:
        return np.c_[np.zeros((n, 2)), rng.uniform(-np.pi, np.pi, n)]
    q = rng.normal(size=(n, 4))
    return np.c_[np.zeros((n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True)]


def lm_then_certify(graph: GraphData, start: np.ndarray | None) -> tuple[float, float, bool, int]:
    """LM on F from ``start`` (``None``: chordal) then the certificate: seconds, F,
    certified, iterations."""
    t0 = time.perf_counter()
    cfg = OptimizerConfig(
        objective="sesync",
        initialization="chordal" if start is None else "vertices",
        stopping=StoppingConfig(max_iterations=LM_ITERATIONS),
    )
    res = optimize(graph, cfg, initial_poses=start)
    cert = certify(graph, res.poses)
    return time.perf_counter() - t0, cert.objective, cert.certified, res.iterations


def main() -> str:
    root = find_data_root()
    rows = [
        "| graph (start) | poses | published F* | staircase [s] | ranks | F (staircase) "
        "| (F − F*)/F* | certified | gap | LM + certify, same start [s] | F (LM) | LM certified "
        "| LM chordal + certify [s] |",
        "|---|---:|---:|---:|---|---:|---:|---|---:|---:|---:|---|---:|",
    ]
    records: list[Record] = []
    loads = [os.getloadavg()]

    def case(name: str, graph: GraphData, start: np.ndarray, f_star: float | None) -> None:
        t_lm, f_lm, ok_lm, _ = lm_then_certify(graph, start)
        t_ch, _, _, _ = lm_then_certify(graph, None)
        t0 = time.perf_counter()
        sc = riemannian_staircase(graph, start)
        t_sc = time.perf_counter() - t0
        ranks = " → ".join(str(s.rank) for s in sc.steps)
        rel = "—" if f_star is None else f"{(sc.objective - f_star) / f_star:+.1e}"
        star = "—" if f_star is None else f"{f_star:.4g}"
        rows.append(
            f"| {name} | {sc.certificate.poses} | {star} | {t_sc:.3g} | {ranks} "
            f"| {sc.objective:.6g} | {rel} | {'yes' if sc.certified else 'no'} "
            f"| {sc.certificate.gap:.2g} | {t_lm:.3g} | {f_lm:.6g} | {'yes' if ok_lm else 'no'} "
            f"| {t_ch:.3g} |"
        )
        records.append(Record(f"{name}: to a certified F*", t_sc, "LM chordal + certify", t_ch))
        loads.append(os.getloadavg())
        print(rows[-1], file=sys.stderr, flush=True)

    graph, winding = ring()
    bad = optimize(
        graph, OptimizerConfig(objective="sesync", initialization="vertices"), initial_poses=winding
    )
    case("ring16 (LM's winding local minimum)", graph, bad.poses, None)
    if root is not None:
        for key, f_star in F_STAR.items():
            path = Path(root) / f"{key}.g2o"
            if path.exists():
                g = read_graph(path)
                case(f"{Path(key).name} (random rotations)", g, random_rotations(g), f_star)
        for key in ("posegraph2d/MIT", "posegraph3d/torus3D"):
            path = Path(root) / f"{key}.g2o"
            if path.exists():  # LM from the file's vertices stops uncertified: the CLI's case
                g = read_graph(path)
                stop = optimize(g, OptimizerConfig(objective="sesync", initialization="vertices"))
                name = f"{Path(key).name} (LM's stop from its vertices, F = {stop.cost:.4g})"
                case(name, g, stop.poses, F_STAR.get(key))
        carlone = Path(root) / "posegraph2d" / "carlone" / "input_INTEL_g2o.g2o"
        if carlone.exists():
            g = read_graph(carlone)
            case("carlone INTEL (its vertices)", g, g.poses, None)
    notes = "\n".join(
        [
            "Time to SE-Sync's certified global optimum (one run per cell, BLAS as the "
            "environment sets it). 'ranks': the staircase's ranks from d (d: the start "
            "certified at once after the trust region). 'gap': F − the verified lower bound "
            "of the final certificate. LM: objective='sesync', at most "
            f"{LM_ITERATIONS} iterations, then certify. F* published by Rosen et al. "
            "(IJRR 2019) to four digits. SE-Sync itself does not run here (C++/MATLAB) and its "
            "published timings are not quoted.",
            "",
            *rows,
            "",
            "Load average (1, 5, 15 min) before the first case and after each: "
            + "; ".join(", ".join(f"{x:.2f}" for x in load) for load in loads)
            + f" ({os.cpu_count()} CPUs shared with other jobs).",
        ]
    )
    return write_results("staircase", records, notes=notes)


if __name__ == "__main__":
    print(main())
