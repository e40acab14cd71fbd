"""How good is the corrected logs' reference? The floor under the laser corpus's corrected part.

The corpus (``bench_laser_corpus.py``) scores the corrected CARMEN logs against their own
poses, which are a SLAM result of their time. Three of them are also raw logs of the Freiburg
benchmark, whose relations were verified by hand: Intel, ACES and Freiburg 079. For each of
those three this benchmark

1. finds every corrected scan in the raw log (the scan with the same range vector: the two
   logs' clocks differ by an offset, and Freiburg 079's do not even agree to 0.1 s);
2. scores the corrected poses on the published relations whose both stamps are such scans;
3. runs graph SLAM with its defaults on the raw log (raw odometry, as a user runs it) and
   scores it on the same relations, and on all of them;
4. scores that raw-log estimate against the corrected poses with the corpus's own drawn
   relations (each scan to the next, to one 2-20 scans on, to one anywhere; seed 1), split
   by kind.

Step 4 is what the corpus's corrected part would say of a result that is better than the
reference where the hand-verified relations can tell. Writes
``results/corrected_reference.{json,md}``. Needs the real data (``SLAMKIT_DATA``).

    python benchmarks/bench_corrected_reference.py
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from _common import RESULTS_DIR, write_results
from bench_laser_corpus import drawn_relations
from slamkit.datasets import LaserScan, Relations, find_data_root, load_dataset
from slamkit.datasets.files import load_file
from slamkit.eval.relations import relation_errors
from slamkit.geometry.pose2 import compose, inverse
from slamkit.pipeline import run

PAIRS = (("intel-raw", "intel"), ("aces-raw", "aces"), ("fr079-raw", "freiburg-079"))
SAME_SCAN = 0.01
"""Two scans are the same when no range differs by more than this [m] (the logs round
ranges differently)."""
SEARCH = 1.0
"""A corrected scan is looked for this far [s] either side of its offset stamp."""


def _scans(data: Any) -> tuple[np.ndarray, list[np.ndarray]]:
    scans = [e for e in data.events if isinstance(e, LaserScan)]
    return np.array([e.t for e in scans]), [np.asarray(e.ranges, dtype=float) for e in scans]


def raw_stamps(raw: Any, corrected: Any) -> np.ndarray:
    """The raw log's stamp of each corrected scan (NaN where none has the same ranges)."""
    rt, rr = _scans(raw)
    ct, cr = _scans(corrected)
    offsets = []
    for k in range(0, len(ct), max(len(ct) // 40, 1)):  # the clock offset, from a few scans
        same = [i for i in range(len(rt)) if _same(rr[i], cr[k])]
        if len(same) == 1:
            offsets.append(rt[same[0]] - ct[k])
    if not offsets:
        return np.full(len(ct), np.nan)
    offset = float(np.median(offsets))
    out = np.full(len(ct), np.nan)
    for k, t in enumerate(ct):
        lo, hi = np.searchsorted(rt, [t + offset - SEARCH, t + offset + SEARCH])
        same = [i for i in range(lo, hi) if _same(rr[i], cr[k])]
        if same:
            out[k] = rt[min(same, key=lambda i: abs(rt[i] - t - offset))]
    return out


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    n = min(a.size, b.size)
    return a.size == b.size and bool(np.all(np.abs(a[:n] - b[:n]) <= SAME_SCAN))


def _kinds(n: int) -> dict[str, slice]:
    """The drawn relations' three kinds (:func:`drawn_relations` keeps them in this order;
    only the last may lose a pair that draws itself)."""
    return {
        "next": slice(0, n - 1),
        "2-20 on": slice(n - 1, 2 * (n - 1)),
        "any": slice(2 * (n - 1), None),
    }


def case(raw_name: str, corrected_name: str, root: Path) -> dict[str, Any]:
    raw = load_dataset(raw_name, data_root=root)
    path = root / "laser" / "corrected_carmen" / f"{corrected_name}-corrected.log.gz"
    corrected = load_file(path, seed=1)
    truth = corrected.truth
    assert truth.times is not None and truth.poses is not None and raw.truth.relations is not None
    stamps = raw_stamps(raw, corrected)
    found = np.isfinite(stamps)
    order = np.argsort(stamps[found], kind="stable")
    T, P = stamps[found][order], truth.poses[found][order]
    keep = np.concatenate([[True], np.diff(T) > 0])
    T, P = T[keep], P[keep]
    # The corrected poses are the laser's, the raw log's relations and estimate the robot's.
    mounting = np.asarray(raw.laser.mounting, dtype=float)
    robot = compose(P, inverse(mounting))
    published = raw.truth.relations
    # 2: the reference on the published relations at its own scans (no interpolation).
    ref = relation_errors(T, robot, published, max_gap=1e-6, stamp_tol=1e-3)
    checked = Relations(ref.t1, ref.t2, published.deltas[ref.covered], source="published")
    cpu = time.process_time()
    result = run("graph-slam", raw, seed=0)
    cpu = time.process_time() - cpu
    ours_same = relation_errors(result.times, result.poses, checked)
    ours_all = relation_errors(result.times, result.poses, published)
    # 4: the raw-log estimate against the reference, by the corpus's drawn relations.
    drawn = drawn_relations(T, P, 1)
    vs = relation_errors(result.times, compose(result.poses, mounting), drawn)
    row: dict[str, Any] = {
        "log": corrected_name,
        "corrected_scans": int(truth.times.size),
        "found_in_raw": int(T.size),
        "published": len(published),
        "checked": int(ref.covered.sum()),
        "reference_m": ref.translation_mean,
        "reference_deg": ref.rotation_mean_deg,
        "ours_same_m": ours_same.translation_mean,
        "ours_same_deg": ours_same.rotation_mean_deg,
        "ours_all_m": ours_all.translation_mean,
        "ours_all_deg": ours_all.rotation_mean_deg,
        "vs_reference_m": vs.translation_mean,
        "vs_reference_deg": vs.rotation_mean_deg,
        "cpu_s": cpu,
    }
    if vs.covered.all():
        for kind, part in _kinds(T.size).items():
            row[f"vs_{kind}_m"] = float(vs.translation_errors[part].mean())
            row[f"vs_{kind}_deg"] = float(vs.rotation_errors_deg[part].mean())
    return row


def _table(rows: list[dict[str, Any]], corpus: dict[str, float]) -> str:
    lines = [
        "| log | corrected scans found in the raw log | published relations checked | "
        "reference on them [m / deg] | graph SLAM (raw log) on them [m / deg] | graph SLAM "
        "(raw log) on all published [m / deg] | graph SLAM (raw log) against the reference, "
        "drawn relations: all / next / 2-20 on / any [m] | rot, all [deg] | the corpus's "
        "corrected row (graph SLAM on synthetic odometry) [m] |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        kinds = " / ".join(
            f"{r.get(f'vs_{k}_m', float('nan')):.3f}" for k in ("next", "2-20 on", "any")
        )
        lines.append(
            f"| {r['log']} | {r['found_in_raw']} of {r['corrected_scans']} | {r['checked']} of "
            f"{r['published']} | {r['reference_m']:.3f} / {r['reference_deg']:.2f} | "
            f"{r['ours_same_m']:.3f} / {r['ours_same_deg']:.2f} | {r['ours_all_m']:.3f} / "
            f"{r['ours_all_deg']:.2f} | {r['vs_reference_m']:.3f} / {kinds} | "
            f"{r['vs_reference_deg']:.2f} | {corpus.get(r['log'], float('nan')):.3f} |"
        )
    return "\n".join(lines)


def main() -> str:
    root = find_data_root()
    if root is None:
        print("bench_corrected_reference: needs the real data (set SLAMKIT_DATA)", file=sys.stderr)
        return ""
    rows = []
    for raw_name, corrected_name in PAIRS:
        rows.append(case(raw_name, corrected_name, root))
        print(json.dumps(rows[-1]), flush=True)
    recorded = json.loads((RESULTS_DIR / "laser_corpus.json").read_text(encoding="utf-8"))
    corpus = {
        r["log"]: r["rel_mean_m"]
        for r in recorded.get("rows", [])
        if r["part"] == "corrected" and r["estimator"] == "graph-slam" and "rel_mean_m" in r
    }
    table = _table(rows, corpus)
    notes = (
        "Graph SLAM with its defaults, seed 0, on the raw log (its own raw odometry). "
        "'Reference': the corrected log's poses, each at the raw stamp of the scan with the same "
        "ranges; scored on the published relations whose both stamps are such scans (no "
        "interpolation), in the robot's frame (the corrected poses are the laser's; Freiburg "
        "079's laser sits 4 cm behind the robot's centre, the estimate is moved there for the "
        "drawn relations). Drawn relations: bench_laser_corpus.drawn_relations of the reference "
        "at those stamps, seed 1, the corpus's metric. The last column is the corpus's recorded "
        "graph-slam row of the same corrected log (results/laser_corpus.json).\n\n" + table
    )
    write_results("corrected_reference", [], notes=notes)
    payload = json.loads((RESULTS_DIR / "corrected_reference.json").read_text(encoding="utf-8"))
    payload["rows"] = rows
    (RESULTS_DIR / "corrected_reference.json").write_text(
        json.dumps(payload, indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
    )
    return table


if __name__ == "__main__":
    print(main())
