"""Victoria Park's GPS fused hierarchically (local maps without GPS joined at a top level of
their base frames, :mod:`slamkit.slam.landmark_graph.hierarchical`) against the flat fused
graph of ``bench_gps_fusion.py``, on the same graph and the same held-out fixes.

Every tenth fix is held out; every estimate is scored on the held-out fixes the GPS track
alone does not reject (:func:`slamkit.eval.gps_holdout.holdout_gps_error`), aligned and
direct. Rows:

* the flat pipeline (the graph without GPS started by growing prefixes, moved into the GPS
  frame, then fused with the χ² gate) and the hierarchy at several submap sizes (gate);
  times are best of ``REPEATS`` runs, flat and hierarchy interleaved, the graph built once
  and not timed; sizes of the largest linear system; the flat objective's χ² (every edge,
  the final weights) at each answer, and the RMS distance of the map's trees from the flat
  graph's;
* artificial dropouts (every fix inside 8 windows of 60 s held out, seeded), scored on the
  fixes inside the windows: prediction across a gap, where following the GPS's slow bias
  does not help;
* a bad local map: inside one 30 s window the readings of the most-seen tree there are
  given the id of the tree farthest from it (a wrong association, as a wrong loop closure
  would be) or of the window's second most-seen tree (a neighbour: the damage stays inside
  one local map), scored on all held-out fixes and on those within 60 s of the window.

Needs the real data (``SLAMKIT_DATA``).

    python benchmarks/bench_gps_hierarchical.py
"""

from __future__ import annotations

import os
import time
from dataclasses import replace
from typing import Any

import numpy as np

from _common import Record, write_results
from slamkit.datasets import find_data_root, load_dataset
from slamkit.eval.gps_holdout import holdout_gps_error
from slamkit.optim.data import EdgeSet
from slamkit.slam.landmark_graph import (
    GpsFixes,
    GraphSolution,
    LandmarkGraph,
    build_landmark_graph,
    fused_start,
    solve_fused,
    solve_hierarchical,
    solve_unfused,
)

HOLDOUT = 10
SIGMA = 1.0  # [m]
SUBMAPS = (25, 50, 100, 200, 400, 1000)  # poses per submap
TIMED = 100  # the submap size timed against the flat pipeline
REPEATS = 3
DROPOUT_S = 60.0
BAD_WINDOW_S = 30.0


def _flat(built: LandmarkGraph) -> tuple[float, float, GraphSolution]:
    """The flat pipeline: unfused solve, move into the GPS frame, fused solve (gate)."""
    t0 = time.perf_counter()
    unfused = solve_unfused(built)
    t1 = time.perf_counter()
    sol = solve_fused(built, *fused_start(built, unfused))
    return t1 - t0, time.perf_counter() - t1, sol


def _map_rms(a: GraphSolution, b: GraphSolution) -> float:
    common, ia, ib = np.intersect1d(a.landmark_ids, b.landmark_ids, return_indices=True)
    d = np.linalg.norm(a.landmarks[ia] - b.landmarks[ib], axis=1)
    return float(np.sqrt(np.mean(d**2))) if common.size else float("nan")


def _bad_map(built: LandmarkGraph, ds_times: np.ndarray, far: bool) -> tuple[LandmarkGraph, float]:
    """``built`` with one wrong association (module docstring): the most-seen tree of a 30 s
    window mid-run given the id of the tree farthest from it (``far``) or of the window's
    second most-seen tree (a neighbour, in the same local map); returns it and the window's
    start [s]."""
    g = built.graph
    k = next(i for i, e in enumerate(g.edges) if e.kind == "range_bearing")
    rb = g.edges[k]
    t_read = ds_times[rb.i]
    t0 = float(ds_times[0] + 0.45 * (ds_times[-1] - ds_times[0]))  # a window mid-run
    inside = (t_read >= t0) & (t_read < t0 + BAD_WINDOW_S)
    ids, counts = np.unique(rb.j[inside], return_counts=True)
    a = int(ids[np.argmax(counts)])
    rows = {int(j): r for r, j in enumerate(g.landmark_ids)}
    pa = g.landmarks[rows[a]]
    if far:
        seen = np.unique(rb.j)
        to = seen[np.argmax([np.linalg.norm(g.landmarks[rows[int(j)]] - pa) for j in seen])]
    else:
        to = ids[np.argsort(counts)[-2]]
    j = rb.j.copy()
    j[inside & (rb.j == a)] = to
    edges = list(g.edges)
    edges[k] = EdgeSet(rb.kind, rb.i, j, rb.measurement, rb.information, rb.lines)
    return replace(built, graph=replace(g, edges=tuple(edges))), t0


def main() -> str:
    root = find_data_root()
    if root is None:
        return "bench_gps_hierarchical: skipped (no real data; set SLAMKIT_DATA)"
    ds = load_dataset("victoria-park", options={"identities": True}, data_root=root)
    truth = ds.truth
    assert truth.position_times is not None and truth.positions is not None
    gps = GpsFixes(truth.position_times, truth.positions, sigma=SIGMA, holdout_every=HOLDOUT)
    load_before = os.getloadavg()[0]
    built = build_landmark_graph(ds, gps=gps)

    def score(sol: GraphSolution, hold: Any = None) -> Any:
        held = gps.held_out if hold is None else hold
        assert sol.lever_arm is not None
        return holdout_gps_error(
            sol.times, sol.poses, gps.times, gps.positions, held, lever_arm=sol.lever_arm
        )

    # Timing: flat pipeline and the hierarchy at TIMED poses per submap, interleaved.
    flat_un, flat_fu, hier_t = [], [], []
    flat: GraphSolution | None = None
    for _ in range(REPEATS):
        t_un, t_fu, flat = _flat(built)
        flat_un.append(t_un)
        flat_fu.append(t_fu)
        t0 = time.perf_counter()
        solve_hierarchical(built, TIMED)
        hier_t.append(time.perf_counter() - t0)
    assert flat is not None and flat.weights is not None and flat.lever_arm is not None
    records = [
        Record(
            f"hierarchical ({TIMED} poses per submap), whole job",
            min(hier_t),
            "flat: unfused + fused",
            min(np.add(flat_un, flat_fu)),
        ),
        Record(
            f"hierarchical ({TIMED} poses per submap), whole job",
            min(hier_t),
            "flat: fused solve alone",
            min(flat_fu),
        ),
    ]
    n_flat = 3 * built.times.shape[0] + 2 * int(built.graph.landmark_ids.shape[0])
    s = score(flat)
    rows = [
        f"| flat (unfused {min(flat_un):.2f} + fused {min(flat_fu):.2f}) | "
        f"{min(np.add(flat_un, flat_fu)):.2f} | {s.rmse:.2f} | {s.direct_rmse:.2f} / "
        f"{s.direct_median:.2f} | ({flat.lever_arm[0]:.2f}, {flat.lever_arm[1]:.2f}) | "
        f"{int((flat.weights < 0.1).sum())} | {n_flat} | {flat.chi2:,.0f} | 0 |"
    ]
    hier: dict[int, GraphSolution] = {}
    for P in SUBMAPS:
        h = solve_hierarchical(built, P)
        x = h.solution
        assert x.lever_arm is not None and x.weights is not None
        hier[P] = x
        s = score(x)
        rows.append(
            f"| hierarchical, {P} poses × {h.submaps} submaps (local {h.local_seconds:.2f} + "
            f"top {h.top_seconds:.2f}) | {x.seconds:.2f} | {s.rmse:.2f} | {s.direct_rmse:.2f} / "
            f"{s.direct_median:.2f} | ({x.lever_arm[0]:.2f}, {x.lever_arm[1]:.2f}) | "
            f"{int((x.weights < 0.1).sum())} | {h.largest_local} local, {h.top_variables} top | "
            f"{x.chi2:,.0f} | {_map_rms(x, flat):.2f} |"
        )
    table = "\n".join(
        [
            "| estimate (solve times [s]) | total [s] | held-out RMSE, aligned [m] | "
            "direct RMSE / median [m] | lever arm [m] | fixes weighted < 0.1 | "
            "largest system [variables] | flat χ² at the answer | trees from flat, RMS [m] |",
            "|---|---:|---:|---:|---|---:|---:|---:|---:|",
            *rows,
        ]
    )

    # Dropouts: 8 windows of DROPOUT_S seconds with every fix held out.
    rng = np.random.default_rng(0)
    t, xy = gps.times, gps.positions
    hold = np.zeros(t.shape[0], dtype=bool)
    for s0 in rng.uniform(t[0], t[-1] - DROPOUT_S, 8):
        hold |= (t >= s0) & (t < s0 + DROPOUT_S)
    b_drop = build_landmark_graph(ds, gps=GpsFixes(t[~hold], xy[~hold], sigma=SIGMA))
    drop_rows = []
    _, _, f_drop = _flat(b_drop)
    sd = score(f_drop, hold)
    drop_rows.append(f"| flat | {int(sd.scored.sum())} | {sd.direct_rmse:.2f} | "
                     f"{sd.direct_median:.2f} | {sd.rmse:.2f} |")  # fmt: skip
    for P in (50, TIMED, 400):
        x = solve_hierarchical(b_drop, P).solution
        sd = score(x, hold)
        drop_rows.append(
            f"| hierarchical, {P} poses | {int(sd.scored.sum())} | "
            f"{sd.direct_rmse:.2f} | {sd.direct_median:.2f} | {sd.rmse:.2f} |"
        )
    drop_table = "\n".join(
        [
            f"| 8 dropouts × {DROPOUT_S:g} s | fixes inside, scored | direct RMSE [m] | "
            "direct median [m] | aligned RMSE [m] |",
            "|---|---:|---:|---:|---:|",
            *drop_rows,
        ]
    )

    # A bad local map: one wrong association inside a 30 s window.
    bad_rows = []
    for far in (True, False):
        b_bad, t_bad = _bad_map(built, built.times, far)
        near = (gps.times >= t_bad - 60.0) & (gps.times < t_bad + BAD_WINDOW_S + 60.0)
        kind = "a far tree" if far else "a neighbour"
        for label, sol in (
            ("flat", _flat(b_bad)[2]),
            (f"hierarchical, {TIMED} poses", solve_hierarchical(b_bad, TIMED).solution),
        ):
            s_all = score(sol)
            s_near = score(sol, gps.held_out & near)
            clean = flat if label == "flat" else hier[TIMED]
            d = np.linalg.norm(sol.poses[:, :2] - clean.poses[:, :2], axis=1)
            bad_rows.append(
                f"| {kind}: {label} | {s_all.direct_rmse:.2f} | {s_near.direct_rmse:.2f} "
                f"({int(s_near.scored.sum())}) | {float(np.max(d)):.2f} | "
                f"{float(np.sqrt(np.mean(d**2))):.2f} |"
            )
    bad_table = "\n".join(
        [
            "| one wrong association | held-out direct RMSE [m] | near it, direct RMSE [m] "
            "(fixes) | path moved, max [m] | path moved, RMS [m] |",
            "|---|---:|---:|---:|---:|",
            *bad_rows,
        ]
    )
    notes = (
        f"Victoria Park, whole run: {built.times.shape[0]} pose nodes, "
        f"{int(built.graph.landmark_ids.shape[0]) - 1} trees, {gps.times.shape[0]} fixes, "
        f"{int(built.fix_in_graph.sum())} fused, every {HOLDOUT}th held out; fix sigma "
        f"{SIGMA:g} m, χ² gate 9.21 for both. Times: best of {REPEATS} (flat and hierarchical "
        f"at {TIMED} poses interleaved); the other submap sizes one run. Load average (1 min) "
        f"{load_before:.1f} before, {os.getloadavg()[0]:.1f} after, on {os.cpu_count()} CPUs. "
        f"The flat χ² is of every edge of the flat fused graph (odometry, readings, fixes at "
        f"the answer's own final weights): how far the answer is from the flat optimum.\n\n"
        f"{table}\n\n{drop_table}\n\nBad local map: window starting at "
        f"{t_bad - built.times[0]:.0f} s into the run; 'path moved' is against the same "
        f"method on the clean data.\n\n{bad_table}"
    )
    return write_results("gps_hierarchical", records, notes=notes)


if __name__ == "__main__":
    print(main())
