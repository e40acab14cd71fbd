"""Laser SLAM on a corpus, with every estimator's defaults: does it hold on logs and
buildings its settings were not chosen on?

Three parts, one row per log and estimator (``graph-slam``, ``laser-odometry``,
``grid-rbpf``), then the median and worst row per estimator and part:

* **raw** — the three raw Freiburg logs as ROS bags (``intel-raw``, ``aces-raw``,
  ``fr079-raw``), their own raw odometry, scored by the benchmark's published relations.
* **corrected** — the eleven corrected CARMEN logs under ``laser/corrected_carmen/``, read
  by path as a user would. Their poses are the truth; the odometry is made from them by
  :func:`slamkit.sim.odometry_errors.corrupt_odometry` with the corpus's error model
  (:class:`~slamkit.sim.odometry_errors.OdometryErrorModel` defaults: random noise per
  metre and per radian, a systematic wheel-radius and wheel-base error of 1-3 %, and rare
  glitches: heading jumps of 30-90°, stalls, duplicated and out-of-order stamps), seeded.
  Scored by ATE (SE(2)-aligned RMSE) and by relations drawn from the true poses
  (:func:`drawn_relations`: each scan to the next, to one 2-20 scans on, and to one anywhere
  in the log).
* **buildings** — generated floor plans (:func:`slamkit.sim.buildings.build_building_dataset`,
  one per seed) with the same odometry error model, scored as the corrected logs; for
  graph SLAM also the closures left in the final graph that disagree with the truth by
  more than 0.5 m or 5° ("wrong closures").

Each run is ``slamkit.pipeline.run`` with the estimator's defaults and seed 0, as ``slamkit
run`` does; its CPU time is the worker process's (``time.process_time``), so two runs in
parallel on the two cores each count only their own work. Needs the real data
(``SLAMKIT_DATA``) for the first two parts.

    python benchmarks/bench_laser_corpus.py [--parts raw corrected buildings]
        [--estimators graph-slam laser-odometry grid-rbpf] [--buildings 20] [--jobs 2]
        [--building-seeds 2 3]   # each building again under these odometry-error seeds
        [--merge]   # re-run some cases, keep the recorded rows of the others
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from _common import RESULTS_DIR, write_results
from slamkit.datasets import Dataset, LaserScan, Relations, find_data_root, load_dataset
from slamkit.datasets.files import load_file
from slamkit.geometry.pose2 import between, interpolate_poses
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.sim.odometry_errors import OdometryErrorModel, corrupt_odometry

RAW = ("intel-raw", "aces-raw", "fr079-raw")
CORRECTED = (
    "acapulco",
    "aces",
    "belgioioso",
    "edmonton",
    "fhw",
    "freiburg-079",
    "freiburg-101",
    "freiburg-campus",
    "intel",
    "orebro",
    "seattle",
)
ESTIMATORS = ("graph-slam", "laser-odometry", "grid-rbpf")
DEFAULT_SEED = 1  # the odometry errors' seed of the corrected logs and of each building's first row
WRONG_CLOSURE = (0.5, np.radians(5.0))
"""A closure whose measurement disagrees with the true relative pose by more than this
(metres, radians) is wrong."""


def drawn_relations(times: np.ndarray, poses: np.ndarray, seed: int) -> Relations:
    """Relations between scans drawn from the true poses: every scan to the next, to one
    2-20 scans on, and to one anywhere in the log (seeded), as ``(t1, t2, δ)`` with ``δ`` the
    pose at ``t2`` in the frame at ``t1``."""
    rng = np.random.default_rng(seed)
    n = times.size
    i = np.arange(n - 1)
    near = np.minimum(i + rng.integers(2, 21, size=i.size), n - 1)
    far = rng.integers(0, n, size=i.size)
    a = np.concatenate([i, i, i])
    b = np.concatenate([i + 1, near, far])
    keep = a != b
    a, b = a[keep], b[keep]
    return Relations(times[a], times[b], between(poses[a], poses[b]), source="drawn")


def _with_relations(data: Dataset, seed: int) -> Dataset:
    truth = data.truth
    assert truth.times is not None and truth.poses is not None
    relations = drawn_relations(truth.times, truth.poses, seed)
    return dataclasses.replace(data, truth=dataclasses.replace(truth, relations=relations))


def load_case(part: str, name: str, seed: int, root: Path | None) -> tuple[Dataset, int]:
    """The data set of one corpus entry and the number of odometry glitches put into it."""
    if part == "raw":
        return load_dataset(name, data_root=root), 0
    if part == "corrected":
        assert root is not None
        path = root / "laser" / "corrected_carmen" / f"{name}-corrected.log.gz"
        data = load_file(path, seed=seed)
    else:
        from slamkit.sim.buildings import build_building_dataset

        data = build_building_dataset(int(name))
    data, glitches = corrupt_odometry(data, OdometryErrorModel(), np.random.default_rng(seed))
    return _with_relations(data, seed), len(glitches)


def wrong_closures(result: Any, data: Dataset) -> tuple[int, int]:
    """``(closures, wrong)`` in graph SLAM's final graph: every edge between keyframes that
    are not consecutive, judged against the true relative pose of its keyframes (each
    keyframe found as the scan whose estimated pose is the graph's, to 1e-9)."""
    graph = result.output.graph
    if graph is None or data.truth.poses is None:
        return 0, 0
    path_t, path_p = result.times, result.poses
    key_t = np.empty(graph.poses.shape[0])
    for k, p in enumerate(graph.poses):
        d = np.abs(path_p[:, :2] - p[:2]).sum(axis=1)
        key_t[k] = path_t[int(np.argmin(d))]
    true = interpolate_poses(data.truth.times, data.truth.poses, key_t)
    index = {int(v): k for k, v in enumerate(graph.pose_ids)}
    closures = wrong = 0
    for edges in graph.edges:
        for i, j, z in zip(edges.i, edges.j, edges.measurement, strict=True):
            if int(j) < 0:
                continue
            a, b = index[int(i)], index[int(j)]
            if abs(a - b) <= 1:
                continue
            closures += 1
            e = between(between(true[a], true[b]), z)
            wrong += bool(np.hypot(e[0], e[1]) > WRONG_CLOSURE[0] or abs(e[2]) > WRONG_CLOSURE[1])
    return closures, wrong


def run_case(part: str, name: str, estimator: str, seed: int, root: Path | None) -> dict[str, Any]:
    """One corpus row: load, run with the defaults, score."""
    data, glitches = load_case(part, name, seed, root)
    if seed != DEFAULT_SEED:
        name = f"{name}/s{seed}"
    cpu = time.process_time()
    try:
        result = run(estimator, data, seed=0)
    except Exception as exc:  # a failure is a row of the corpus, not the end of it
        return {"part": part, "log": name, "estimator": estimator, "error": f"{exc}"[:200]}
    cpu = time.process_time() - cpu
    scores = evaluate(result, data).scores
    row: dict[str, Any] = {
        "part": part,
        "log": name,
        "estimator": estimator,
        "cpu_s": cpu,
        "scans": sum(1 for e in data.events if isinstance(e, LaserScan)),
        "glitches": glitches,
    }
    rel = scores.relations
    if rel is not None and hasattr(rel, "translation_mean"):
        row["rel_mean_m"] = rel.translation_mean
        row["rel_std_m"] = rel.translation_std
        row["rel_median_m"] = float(np.median(rel.translation_errors))
        row["rel_rot_deg"] = rel.rotation_mean_deg
    ate = scores.ate
    if ate is not None and hasattr(ate, "rmse"):
        row["ate_m"] = ate.rmse
    row["warnings"] = sorted({getattr(w, "kind", "consistency") for w in scores.warnings})
    d = result.output.diagnostics
    for key in ("odometry_overridden", "lost"):
        if key in d:
            row[key] = d[key]
    if estimator == "graph-slam" and data.truth.poses is not None:
        row["closures"], row["wrong_closures"] = wrong_closures(result, data)
    return row


def _log_key(log: str) -> tuple[int, str, int]:
    """Buildings by number, then odometry seed; logs by name."""
    head, _, seed = log.partition("/s")
    return (int(head), "", int(seed or DEFAULT_SEED)) if head.isdigit() else (-1, log, 0)


def _cell(row: dict[str, Any], key: str, fmt: str) -> str:
    return format(row[key], fmt) if key in row else "—"


def _table(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| part | log | estimator | relations, mean ± std [m] | median [m] | rot [deg] | ATE [m] "
        "| closures (wrong) | glitches (overridden) | warnings | CPU [s] |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---|---:|",
    ]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['part']} | {r['log']} | {r['estimator']} | failed: {r['error']} |")
            continue
        rel = f"{r['rel_mean_m']:.3f} ± {r['rel_std_m']:.3f}" if "rel_mean_m" in r else "—"
        closures = f"{r['closures']} ({r['wrong_closures']})" if "closures" in r else "—"
        glitches = f"{r['glitches']}" + (
            f" ({r['odometry_overridden']})" if "odometry_overridden" in r else ""
        )
        lines.append(
            f"| {r['part']} | {r['log']} | {r['estimator']} | {rel} | "
            f"{_cell(r, 'rel_median_m', '.3f')} | {_cell(r, 'rel_rot_deg', '.2f')} | "
            f"{_cell(r, 'ate_m', '.3f')} | {closures} | {glitches} | "
            f"{', '.join(r['warnings']) or '—'} | {r['cpu_s']:.0f} |"
        )
    return "\n".join(lines)


def _summary(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| part | estimator | logs | failed | median of the logs' mean relation error [m] "
        "| worst [m] (log) | median ATE [m] | worst ATE [m] (log) | wrong closures | CPU [s] |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for part in ("raw", "corrected", "buildings"):
        for est in ESTIMATORS:
            mine = [r for r in rows if r["part"] == part and r["estimator"] == est]
            if not mine:
                continue
            ok = [r for r in mine if "error" not in r]
            failed = len(mine) - len(ok)
            rel = [(r["rel_mean_m"], r["log"]) for r in ok if "rel_mean_m" in r]
            ate = [(r["ate_m"], r["log"]) for r in ok if "ate_m" in r]
            wrong = sum(r.get("wrong_closures", 0) for r in ok)
            cpu = sum(r["cpu_s"] for r in ok)
            med_rel = f"{np.median([v for v, _ in rel]):.3f}" if rel else "—"
            worst_rel = "{:.3f} ({})".format(*max(rel)) if rel else "—"
            med_ate = f"{np.median([v for v, _ in ate]):.3f}" if ate else "—"
            worst_ate = "{:.3f} ({})".format(*max(ate)) if ate else "—"
            wrong_s = str(wrong) if est == "graph-slam" else "—"
            lines.append(
                f"| {part} | {est} | {len(mine)} | {failed} | {med_rel} | {worst_rel} | "
                f"{med_ate} | {worst_ate} | {wrong_s} | {cpu:.0f} |"
            )
    return "\n".join(lines)


def main() -> str:
    parser = argparse.ArgumentParser()
    parser.add_argument("--parts", nargs="*", default=["raw", "corrected", "buildings"])
    parser.add_argument("--estimators", nargs="*", default=list(ESTIMATORS))
    parser.add_argument("--logs", nargs="*", default=None, help="only these logs / seeds")
    parser.add_argument("--buildings", type=int, default=20)
    parser.add_argument("--seed", type=int, default=DEFAULT_SEED, help="the odometry errors' seed")
    parser.add_argument(
        "--building-seeds",
        type=int,
        nargs="*",
        default=[],
        help="more odometry-error seeds for the buildings (rows named BUILDING/sSEED)",
    )
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument(
        "--merge",
        action="store_true",
        help="keep the recorded rows of the cases not run now (results/laser_corpus.json)",
    )
    args = parser.parse_args()
    root = find_data_root()
    cases: list[tuple[str, str]] = []
    if root is not None and "raw" in args.parts:
        cases += [("raw", n) for n in RAW]
    if root is not None and "corrected" in args.parts:
        cases += [("corrected", n) for n in CORRECTED]
    if "buildings" in args.parts:
        cases += [("buildings", str(s)) for s in range(args.buildings)]
    if args.logs:
        cases = [c for c in cases if c[1] in args.logs]
    jobs = [(p, n, e, args.seed) for p, n in cases for e in args.estimators]
    jobs += [
        ("buildings", n, e, s)
        for p, n in cases
        if p == "buildings"
        for s in args.building_seeds
        if s != args.seed
        for e in args.estimators
    ]
    wall = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(run_case, p, n, e, s, root) for p, n, e, s in jobs]
        rows = []
        for f in futures:
            rows.append(f.result())
            print(_table([rows[-1]]).splitlines()[-1], flush=True)
    wall = time.perf_counter() - wall
    if args.merge:
        done = {(r["part"], r["log"], r["estimator"]) for r in rows}
        recorded = json.loads((RESULTS_DIR / "laser_corpus.json").read_text(encoding="utf-8"))
        rows += [r for r in recorded["rows"] if (r["part"], r["log"], r["estimator"]) not in done]
    order = {p: k for k, p in enumerate(("raw", "corrected", "buildings"))}
    rows.sort(key=lambda r: (order[r["part"]], r["estimator"], _log_key(r["log"])))
    total_cpu = sum(r.get("cpu_s", 0.0) for r in rows)
    notes = (
        f"Every estimator with its defaults, seed 0; odometry errors seed {args.seed} "
        "(OdometryErrorModel defaults) on the corrected logs and the buildings, and on the "
        "buildings the further seeds of the rows named BUILDING/sSEED. Raw logs: the "
        "published relations; corrected logs and buildings: relations drawn from the true "
        "poses (each scan to the next, to one 2-20 scans on, to one anywhere), ATE SE(2)-"
        f"aligned. CPU is each run's own process time. The whole corpus: {total_cpu:.0f} s of "
        f"CPU, {wall:.0f} s of wall time on {args.jobs} workers. No peer runs here; the "
        "published figures of the raw logs are in laser_graph.md.\n\n"
        + _summary(rows)
        + "\n\n"
        + _table(rows)
    )
    write_results("laser_corpus", [], notes=notes)
    payload = json.loads((RESULTS_DIR / "laser_corpus.json").read_text(encoding="utf-8"))
    payload["rows"] = rows
    (RESULTS_DIR / "laser_corpus.json").write_text(
        json.dumps(payload, indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
    )
    return _summary(rows)


if __name__ == "__main__":
    print(main())
