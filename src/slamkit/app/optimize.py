"""``optimize_graph_job``: a pose-graph or landmark-graph file → the optimised graph, plots,
metrics and the resolved configuration, in one folder written completely or not at all.

Files written (``OUT`` the output folder):

* ``optimized.g2o`` or ``optimized.graph`` — the graph with its vertices set to the optimum,
  in the input's format family: g2o in → g2o out, TORO/hog-man in → TORO out. iSAM and
  GTSAM files have no vertex lines, so their graphs are written as g2o; g2o has one id space
  for poses and landmarks, so when landmark ids collide with pose ids every landmark id is
  shifted by ``landmark_id_offset`` (the largest pose id + 1), in its vertex and its edges.
  A TORO file has no landmark vertices: the landmarks of a TORO graph (``BR`` lines) go to
  ``landmarks.csv`` (``id,x,y``). ``metrics.json`` and ``config.json`` say which of these
  happened (``output``).
* ``graph.png`` — the graph at its initial values and optimised, side by side (x-y
  projection for 3D graphs), with the loop closures and landmarks.
* ``metrics.json`` — ``chi2_initial``/``chi2_final`` (g2o's χ² of every edge, whatever the
  objective minimised), ``sesync_objective_initial``/``_final`` (SE-Sync's F over the
  relative-pose edges), ``cost_initial``/``cost_final`` (the objective minimised, with the
  robust kernel), ``start`` (``requested``, ``used``, the cost of every start compared in
  ``costs`` and the ``reason``), ``information_repair`` (``mode``, the exact count
  ``repaired`` of edges whose information was clamped, per tag, the first 20 as
  ``file:line``), ``iterations``, ``factorizations``, ``linear_iterations`` (V-cycles or
  sweeps of ``mlr`` / ``gauss_seidel``), ``converged``, ``reason``, counts,
  solver and linear solver, the per-iteration history and the times: ``solve_seconds`` is
  the optimiser alone (sparsity pattern, symbolic analysis and iterations; not reading,
  validating or initialising, which are ``read_seconds``, ``validate_seconds`` and
  ``init_seconds``). With ``certify``: ``certificate`` (SE-Sync's global-optimality
  certificate of the solution, :class:`~slamkit.optim.Certificate`: ``certified``,
  ``lambda_min``, ``lambda_lower``, ``tolerance``, ``q_norm``, ``objective``, ``lower_bound``,
  ``gap``, ``poses``, ``seconds``). With ``staircase`` as well, when that certificate fails:
  ``staircase`` (:class:`~slamkit.optim.StaircaseResult`: ``certified``, ``objective`` = the
  certified ``F*``, ``relaxation_objective``, ``ranks_climbed``, ``final_rank``, each rank's
  ``steps``, the rounded poses' ``certificate``, ``seconds``, ``chi2`` of those poses and
  ``written``); when it certifies, the graph file and ``graph.png`` hold the staircase's
  poses (the other ``*_final`` keys stay LM's), else LM's.
* ``config.json`` — the resolved options and the full optimiser configuration
  (``optimizer``: :class:`~slamkit.optim.OptimizerConfig` with its sections as nested
  objects, readable by :func:`~slamkit.config.config_from_mapping`).
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.paths import find_data_file, find_data_root
from slamkit.errors import ConfigError, DataNotFoundError, InputError
from slamkit.io import atomic_folder, write_json
from slamkit.io.graphfiles.families import FAMILIES, LANDMARK_KINDS, POSE_PAIR_KINDS
from slamkit.io.graphfiles.reader import MAX_REPORTED_LINES, REPAIR_MODES, RepairedEdge
from slamkit.io.posegraph import RepairWarning, read_graph_report, repair_summary, write_graph
from slamkit.optim import (
    GraphData,
    GraphProblem,
    IterationInfo,
    OptimizerConfig,
    OptimizeResult,
    certify,
    choose_start,
    g2o_chi2,
    optimize,
    riemannian_staircase,
    sesync_objective,
)
from slamkit.optim.certificate import check_certifiable
from slamkit.optim.repair import REPAIR_RTOL

if TYPE_CHECKING:
    from slamkit.io.graphfiles.reader import RepairMode
    from slamkit.optim.data import GraphFamily
    from slamkit.optim.settings import InitName
    from slamkit.viz.plots import Figure  # app never imports matplotlib itself

__all__ = ["OptimizeReport", "OptimizeRequest", "find_graph_file", "optimize_graph_job"]

SOLVERS = ("lm", "gn", "dogleg", "mlr", "gauss_seidel")
INITS = ("auto", "file", "odometry", "chordal", "grow")
OBJECTIVES = ("g2o", "sesync")
KERNELS = ("none", "huber", "cauchy", "geman_mcclure", "dcs")
_INIT_METHOD: dict[str, InitName] = {
    "auto": "auto",
    "file": "vertices",
    "odometry": "odometry",
    "chordal": "chordal",
    "grow": "grow",
}
_SUFFIX = {"g2o": ".g2o", "toro": ".graph"}
_FAMILY_TITLE = {"g2o": "g2o", "toro": "TORO", "isam": "iSAM", "gtsam": "GTSAM"}


@dataclass(frozen=True)
class OptimizeRequest:
    """The options of one ``slamkit optimize`` run."""

    path: Path
    """The graph file (g2o, TORO/hog-man ``.graph``, iSAM/GTSAM ``.txt``; ``.gz`` allowed)."""
    out_dir: Path
    """The output folder (written atomically; an existing non-empty one needs ``overwrite``)."""
    solver: str = "lm"
    """``"lm"``, ``"gn"``, ``"dogleg"``, ``"mlr"`` (multilevel relaxation, 2D pose graphs) or
    ``"gauss_seidel"`` (``"gauss-seidel"`` too)."""
    init: str | None = None
    """``"file"`` (the file's vertices), ``"odometry"`` (spanning tree), ``"chordal"`` or
    ``"grow"`` (batch solves over growing time-ordered prefixes,
    :func:`~slamkit.optim.grow_initialization`); ``None`` or ``"auto"``: chosen by
    :func:`~slamkit.optim.choose_start`: on a pose graph the lower-cost of the file's
    vertices (odometry when it has none) and chordal, on a landmark graph the file's vertices,
    else grow (their chordal or odometry start lies in a bad basin: Victoria Park). The
    metrics' ``start`` says which and why."""
    robust_kernel: str = "none"
    """``"none"``, ``"huber"``, ``"cauchy"``, ``"geman_mcclure"`` (or ``geman-mcclure``),
    ``"dcs"``."""
    robust_width: float | None = None
    """Kernel width (``None``: the kernel's default width in the optimiser; units in
    :mod:`slamkit.optim.robust`)."""
    objective: str = "g2o"
    """``"g2o"`` (the file's χ²) or ``"sesync"`` (SE-Sync's F on the relative-pose edges)."""
    max_iterations: int | None = None
    """Linearisations at most (``None``: the optimiser's default, 100)."""
    repair_information: str = "none"
    """``"none"``: an information matrix that is not positive definite is an error naming
    its line; ``"clamp"``: it is repaired by eigenvalue clamping
    (:mod:`slamkit.optim.repair`) and every repaired edge is counted in the metrics'
    ``information_repair``."""
    plots: bool = True
    overwrite: bool = False
    certify: bool = False
    """Certify the solution globally optimal (SE-Sync's certificate,
    :func:`~slamkit.optim.certify`): needs ``objective="sesync"`` and a graph of
    relative-pose edges only; the metrics' ``certificate`` holds the result."""
    staircase: bool = False
    """With ``certify``: when the solution is not certified, run the Riemannian staircase
    (:func:`~slamkit.optim.riemannian_staircase`) from it and write its certified optimum;
    the metrics' ``staircase`` holds the ranks climbed and ``F*``."""


@dataclass(frozen=True)
class OptimizeReport:
    """What :func:`optimize_graph_job` wrote and measured."""

    out_dir: Path
    files: tuple[str, ...]
    graph_file: str
    metrics: dict[str, Any]
    config: dict[str, Any]
    result: OptimizeResult


def _choice(value: str, name: str, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        raise ConfigError(f"{name}: expected one of {', '.join(allowed)}, got {value!r}")
    return value


def _optimizer_config(request: OptimizeRequest) -> OptimizerConfig:
    """Check the request's options and build the optimiser's configuration (errors name the
    option)."""
    robust: dict[str, Any] = {
        "kernel": _choice(request.robust_kernel.replace("-", "_"), "robust kernel", KERNELS)
    }
    settings: dict[str, Any] = {
        "solver": _choice(request.solver.replace("-", "_"), "solver", SOLVERS),
        "objective": _choice(request.objective, "objective", OBJECTIVES),
        "robust": robust,
    }
    if request.init is not None:
        _choice(request.init, "init", INITS)
    _choice(request.repair_information, "repair information", REPAIR_MODES)
    if request.robust_width is not None:
        robust["width"] = request.robust_width
    if request.max_iterations is not None:
        settings["stopping"] = {"max_iterations": request.max_iterations}
    if request.certify and request.objective != "sesync":
        raise ConfigError(
            "certify: the certificate is for SE-Sync's objective; add --objective sesync"
        )
    if request.staircase and not request.certify:
        raise ConfigError("staircase: it runs when the certificate fails; add --certify")
    return config_from_mapping(OptimizerConfig, settings, "optimize")


@dataclass(frozen=True)
class _Output:
    graph: GraphData  # what goes into the graph file
    family: GraphFamily
    name: str
    landmarks_csv: bool
    landmark_id_offset: int
    notes: tuple[str, ...]


def _family_holds(graph: GraphData, family: str) -> bool:
    """Whether a file of ``family`` can hold the optimised graph's poses, edges, fixed poses
    and equivalences (landmark vertices may go to a side file)."""
    spec = FAMILIES[family]
    if spec.pose_vertex(graph.dim) is None:
        return False
    if any(e.kind not in spec.write_edge for e in graph.edges):
        return False
    if graph.fixed_ids.size and spec.fix_tag is None:
        return False
    return not (graph.equivalences.size and spec.equiv_tag is None)


def _output(data: GraphData, result: OptimizeResult) -> _Output:
    """Choose the output family (the input's, else g2o, else TORO) and make the graph fit."""
    graph = result.as_graph(data)
    candidates: list[GraphFamily] = list(dict.fromkeys([data.family, "g2o", "toro"]))
    family = next((f for f in candidates if f in FAMILIES and _family_holds(graph, f)), None)
    if family is None:
        kinds = ", ".join(sorted({e.kind for e in graph.edges}))
        raise InputError(
            f"{data.source or 'the graph'}: no graph-file family holds vertices and edges of "
            f"kinds {kinds}"
        )
    notes: list[str] = []
    if family != data.family:
        notes.append(
            f"{_FAMILY_TITLE.get(data.family, data.family)} files cannot hold vertices: "
            f"the optimised graph is written as {_FAMILY_TITLE[family]}"
        )
    offset = 0
    landmarks_csv = graph.landmark_ids.size > 0 and FAMILIES[family].landmark_vertex() is None
    if landmarks_csv:
        notes.append(
            f"{_FAMILY_TITLE[family]} files have no landmark vertices: the optimised landmarks "
            "are in landmarks.csv"
        )
        graph = dataclasses.replace(
            graph, landmark_ids=np.zeros(0, dtype=np.int64), landmarks=np.zeros((0, 2))
        )
    elif np.intersect1d(graph.pose_ids, graph.landmark_ids).size:
        # One id space for poses and landmarks in the file: shift every landmark id.
        offset = int(graph.pose_ids.max()) + 1
        edges = tuple(
            dataclasses.replace(e, j=e.j + offset) if e.kind in LANDMARK_KINDS else e
            for e in graph.edges
        )
        graph = dataclasses.replace(graph, landmark_ids=graph.landmark_ids + offset, edges=edges)
        notes.append(
            f"landmark ids collide with pose ids: every landmark id is written as id + {offset}"
        )
    return _Output(
        graph, family, "optimized" + _SUFFIX[family], landmarks_csv, offset, tuple(notes)
    )


def _pose_edge_rows(data: GraphData, pose_ids: np.ndarray) -> np.ndarray:
    """``(E, 2)`` rows (into ``pose_ids``) of the relative-pose edges, for the plot."""
    order = np.argsort(pose_ids, kind="stable")
    sorted_ids = pose_ids[order]
    pairs = [np.column_stack([e.i, e.j]) for e in data.edges if e.kind in POSE_PAIR_KINDS]
    if not pairs:
        return np.zeros((0, 2), dtype=np.int64)
    ids = np.concatenate(pairs)
    return order[np.searchsorted(sorted_ids, ids)]


def _write_landmarks_csv(path: Path, ids: np.ndarray, landmarks: np.ndarray) -> None:
    rows = [f"{int(k)},{float(x)!r},{float(y)!r}" for k, (x, y) in zip(ids, landmarks, strict=True)]
    path.write_text("id,x,y\n" + "".join(r + "\n" for r in rows), encoding="utf-8")


def _history(history: tuple[IterationInfo, ...]) -> list[dict[str, Any]]:
    return [
        {
            "iteration": h.iteration,
            "cost": h.cost,
            "chi2": h.chi2,
            "step_norm": h.step_norm,
            "accepted": h.accepted,
            "damping": h.damping,
        }
        for h in history
    ]


def _repair_mode(request: OptimizeRequest) -> RepairMode:
    return "clamp" if request.repair_information == "clamp" else "none"


def _start_label(name: str) -> str:
    """The CLI's name of a library start (the file's vertices are ``file``)."""
    return "file" if name == "vertices" else name


def _resolve_init(init: str | None, data: GraphData) -> str:
    has_vertices = data.poses.shape[0] > 0
    if init is None:
        return "auto"
    if init == "file" and not has_vertices:
        raise ConfigError(
            f"init 'file': {data.source or 'the graph'} has no vertex lines; use odometry or "
            "chordal"
        )
    return init


def _repair_record(mode: str, path: Path, repaired: tuple[RepairedEdge, ...]) -> dict[str, Any]:
    """The metrics' ``information_repair``: the mode, the exact count (and per tag), the
    first edges as ``file:line`` with their eigenvalues, and the warning's sentence."""
    by_tag: dict[str, int] = {}
    for r in repaired:
        by_tag[r.tag] = by_tag.get(r.tag, 0) + 1
    return {
        "mode": mode,
        "floor_relative_to_largest_eigenvalue": REPAIR_RTOL if mode == "clamp" else None,
        "repaired": len(repaired),
        "repaired_by_tag": by_tag,
        "first": [
            {
                "location": f"{path}:{r.line}",
                "tag": r.tag,
                "eigenvalue_min": r.eigenvalue_min,
                "eigenvalue_max": r.eigenvalue_max,
            }
            for r in repaired[:MAX_REPORTED_LINES]
        ],
        "warning": repair_summary(path, repaired) if repaired else None,
    }


def _metrics(
    data: GraphData,
    path: Path,
    init: str,
    start_record: dict[str, Any],
    cfg: OptimizerConfig,
    start: tuple[np.ndarray, np.ndarray],
    result: OptimizeResult,
    output: _Output,
    seconds: dict[str, float],
) -> dict[str, Any]:
    p0, l0 = start
    return {
        "chi2_initial": g2o_chi2(data, p0, l0),
        "chi2_final": g2o_chi2(data, result.poses, result.landmarks),
        "sesync_objective_initial": sesync_objective(data, p0),
        "sesync_objective_final": sesync_objective(data, result.poses),
        "cost_initial": result.initial_cost,
        "cost_final": result.cost,
        "iterations": result.iterations,
        "factorizations": result.factorizations,
        "linear_iterations": result.linear_iterations,
        "converged": result.converged,
        "reason": result.reason,
        "solve_seconds": result.total_seconds,
        **seconds,
        "setup_seconds": result.setup_seconds,
        "assembly_seconds": result.assembly_seconds,
        "factor_seconds": result.factor_seconds,
        "solver": result.method,
        "objective": result.objective,
        "initialization": init,
        "start": start_record,
        "robust_kernel": cfg.robust.kernel,
        "linear_solver": result.linear_solver,
        "anchored_first_pose": result.anchored_first,
        "dim": data.dim,
        "poses": int(result.pose_ids.shape[0]),
        "landmarks": int(result.landmark_ids.shape[0]),
        "edges": data.n_edges,
        "edges_by_kind": {e.kind: len(e) for e in data.edges},
        "fixed_poses": int(data.fixed_ids.shape[0]),
        "equivalences": int(data.equivalences.shape[0]),
        "input": {"file": str(path), "family": data.family},
        "output": {
            "graph_file": output.name,
            "family": output.family,
            "landmarks_file": "landmarks.csv" if output.landmarks_csv else None,
            "landmark_id_offset": output.landmark_id_offset,
            "notes": list(output.notes),
        },
        "history": _history(result.history),
    }


def _figure(
    data: GraphData,
    path: Path,
    start: tuple[np.ndarray, np.ndarray],
    result: OptimizeResult,
    metrics: dict[str, Any],
) -> Figure:
    from slamkit.viz.graphs import pose_graph_figure, principal_plane  # plotting only when asked

    p0, l0 = start
    lm = result.landmark_ids.shape[0] > 0
    what = f"{metrics['poses']} poses, {metrics['landmarks']} landmarks, {metrics['edges']} edges"
    labels = ("x [m]", "y [m]")
    xy0, xy1 = p0[:, :2], result.poses[:, :2]
    if data.dim == 3 and not lm:  # the plane the poses mostly lie in, not always x-y
        xy0, xy1, labels = principal_plane(p0[:, :3], result.poses[:, :3])
    return pose_graph_figure(
        xy0,
        xy1,
        edges=_pose_edge_rows(data, result.pose_ids),
        initial_landmarks=l0 if lm else None,
        optimized_landmarks=result.landmarks if lm else None,
        titles=(
            f"initial ({metrics['initialization']}): χ² = {metrics['chi2_initial']:.6g}",
            f"optimised ({result.method}, {result.iterations} iterations): "
            f"χ² = {metrics['chi2_final']:.6g}",
        ),
        suptitle=f"{path.name}: {what}"
        + (" (projected on its principal plane)" if labels[0] != "x [m]" else "")
        + (" (x-y projection)" if data.dim == 3 and lm else ""),
        axis_labels=labels,
    )


def _staircase(
    data: GraphData, result: OptimizeResult, output: _Output, metrics: dict[str, Any]
) -> tuple[OptimizeResult, _Output]:
    """The staircase from ``result``'s refused poses, recorded in ``metrics``; when it
    certifies, the result and output that carry its poses, else the given ones (an
    uncertified rounding is no better evidence than LM's answer)."""
    sc = riemannian_staircase(data, result.poses)
    chi2 = g2o_chi2(data, sc.poses, result.landmarks)
    metrics["staircase"] = {**sc.as_dict(), "chi2": chi2, "written": sc.certified}
    rank = sc.steps[-1].rank
    if sc.certified:
        result = dataclasses.replace(
            result, poses=sc.poses, sesync_objective=sc.objective, g2o_chi2=chi2
        )
        output = _output(data, result)
        note = (
            "the solution was not certified; the Riemannian staircase's certified global "
            f"optimum is written (F = {sc.objective:.6g}, found at rank {rank})"
        )
    else:
        note = (
            f"the solution was not certified, nor was the Riemannian staircase's by rank {rank} "
            f"(F = {sc.objective:.6g}); the optimiser's poses are written"
        )
    output = dataclasses.replace(output, notes=(*output.notes, note))
    metrics["output"]["notes"] = list(output.notes)
    return result, output


def find_graph_file(path: str | Path, data_root: str | Path | None = None) -> Path:
    """``path`` if it exists, else the same relative path under the data folder
    (``SLAMKIT_DATA``, :func:`~slamkit.datasets.paths.find_data_file`), so
    ``posegraph2d/intel.g2o`` names the shared file from anywhere; neither:
    :class:`~slamkit.errors.DataNotFoundError` saying where it looked."""
    found = find_data_file(path, data_root)
    if found is not None:
        return found
    p = Path(path).expanduser()
    root = find_data_root(data_root)
    where = "" if root is None or p.is_absolute() else f" (nor under the data folder {root})"
    raise DataNotFoundError(f"{p}: not found{where}")


def optimize_graph_job(
    request: OptimizeRequest,
    progress: Callable[[int, int], None] | None = None,
    iterations: Callable[[IterationInfo], None] | None = None,
) -> OptimizeReport:
    """Read ``request.path``, optimise it and write the files of the module docstring into
    ``request.out_dir``. ``progress(iteration, max_iterations)`` runs after every iteration,
    and ``iterations(info)`` with the iteration's record (χ², cost, step, times).

    Bad options raise :class:`~slamkit.errors.ConfigError` before the file is read; a
    malformed file raises :class:`~slamkit.errors.DatasetFormatError` naming the file and
    line; a graph the optimiser cannot take (missing vertices, no gauge, disconnected, bad
    information) raises the typed error of :class:`~slamkit.optim.GraphProblem`; an existing
    non-empty output folder without ``overwrite`` is an :class:`~slamkit.errors.InputError`.
    Nothing is written then.
    """
    cfg = _optimizer_config(request)
    path = Path(request.path)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        # The report carries every repaired edge; the caller shows the warning's sentence.
        warnings.simplefilter("ignore", RepairWarning)
        read = read_graph_report(path, repair_information=_repair_mode(request))
    data = read.graph
    if request.certify:
        check_certifiable(data)  # before any work: relative-pose edges only
    repair = _repair_record(request.repair_information, path, read.repaired)
    t1 = time.perf_counter()
    problem = GraphProblem.from_data(data, objective=cfg.objective, gauge=cfg.gauge)
    t2 = time.perf_counter()
    requested = _resolve_init(request.init, data)
    cfg = dataclasses.replace(cfg, initialization=_INIT_METHOD[requested])

    def on_iteration(info: IterationInfo) -> None:
        if progress is not None:
            progress(info.iteration, cfg.stopping.max_iterations)
        if iterations is not None:
            iterations(info)

    # The folder check comes before the work; on any error the partial folder is removed.
    with atomic_folder(request.out_dir, overwrite=request.overwrite) as tmp:
        choice = choose_start(problem, cfg)
        p0, l0 = choice.poses, choice.landmarks
        init = _start_label(choice.name)
        start_record = {
            "requested": requested,
            "used": init,
            "costs": {_start_label(k): v for k, v in choice.costs.items()},
            "reason": choice.reason,
        }
        # The start used, so that config.json re-runs exactly this solve.
        cfg = dataclasses.replace(cfg, initialization=_INIT_METHOD[init])
        t3 = time.perf_counter()
        result = optimize(
            data, cfg, initial_poses=p0, initial_landmarks=l0, callback=on_iteration,
            problem=problem,
        )  # fmt: skip
        output = _output(data, result)
        seconds = {"read_seconds": t1 - t0, "validate_seconds": t2 - t1, "init_seconds": t3 - t2}
        metrics = _metrics(data, path, init, start_record, cfg, (p0, l0), result, output, seconds)
        metrics["information_repair"] = repair
        if request.certify:
            metrics["certificate"] = certify(data, result.poses).as_dict()
            if request.staircase and not metrics["certificate"]["certified"]:
                result, output = _staircase(data, result, output, metrics)
        resolved = {
            "file": str(path),
            "solver": result.method,
            "init": init,
            "robust_kernel": cfg.robust.kernel,
            "robust_width": cfg.kernel.width if cfg.robust.kernel != "none" else None,
            "objective": cfg.objective,
            "max_iterations": cfg.stopping.max_iterations,
            "repair_information": request.repair_information,
            "certify": request.certify,
            "staircase": request.staircase,
            "output": metrics["output"],
            "optimizer": config_to_dict(cfg),
        }
        write_graph(output.graph, tmp / output.name, family=output.family)
        if output.landmarks_csv:
            _write_landmarks_csv(tmp / "landmarks.csv", result.landmark_ids, result.landmarks)
        write_json(tmp / "metrics.json", metrics)
        write_json(tmp / "config.json", resolved)
        if request.plots:
            from slamkit.viz import save_figure

            save_figure(_figure(data, path, (p0, l0), result, metrics), tmp / "graph.png")
        files = tuple(sorted(p.name for p in tmp.iterdir()))
    return OptimizeReport(Path(request.out_dir), files, output.name, metrics, resolved, result)
