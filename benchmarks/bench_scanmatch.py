"""Scan-to-scan matching: slamkit's point-to-line ICP (PLICP) and point-to-point ICP against a
straightforward NumPy ICP and Open3D's ICP, on the same pairs in the same run.

Pairs:

* **simulated**: ``random_scan_pairs`` in the rooms world (seed 0), 180 beams over 180°,
  20 m range, 1 cm range noise, true motion 0.3 m and 10° between the scans;
* **real**: consecutive scans of the corrected Intel CARMEN log (180 beams, 80 m; every
  other pair), reference motion ``between(truth_k, truth_k+1)`` of the corrected laser poses
  (skipped with a printed reason when the data is absent).

The initial guess is the true (reference) motion composed with an offset of a stated size in
a random direction and a random rotation sign, drawn per pair from a seeded generator.
A match succeeds when it returns (no ``MatchError``) within 5 cm and 1° of the truth
(simulated) or 10 cm and 2° (real: the corrected poses are themselves estimates).

Methods, all starting from the points of the two scans (trees, normals and any other set-up
are timed):

* ``plicp``, ``icp``: :func:`slamkit.scanmatch.plicp`, :func:`slamkit.scanmatch.icp` with
  their default configs (1 m correspondence distance); ``plicp`` runs the compiled kernels of
  :mod:`slamkit.scanmatch.kernels` when numba is installed;
* ``plicp-numpy``: the same PLICP on the NumPy backend
  (``slamkit.backend.SEAM.use(Backend.NUMPY)``): the NumPy path, cKDTree queries, the same
  answers to rounding;
* ``numpy-icp``: point-to-point ICP written here in plain NumPy, brute-force nearest
  neighbours (a full distance matrix per iteration), the same trimming (best 90% within 1 m)
  and stopping rule (step below 1e-4 m and 1e-4 rad, at most 100 iterations);
* ``open3d-p2p``, ``open3d-p2plane``: ``open3d.pipelines.registration.registration_icp``
  with the 2D points at z = 0, 1 m correspondence distance, at most 100 iterations,
  Open3D's default relative fitness/RMSE thresholds (1e-6); for point-to-plane the target
  normals are estimated by Open3D (``estimate_normals``, 15 nearest neighbours) on a copy of
  the reference extruded to z = ±0.05 m, since all normals of a flat cloud are vertical, and
  their z part is dropped (a tilted normal couples in roll and pitch);
* ``correlative``, ``normal-icp``: slamkit's other matchers on the same pairs (not peers):
  :func:`slamkit.scanmatch.correlative_match` with its default window (±0.5 m, ±20°,
  branch and bound; the reference rasterised in each call) and
  :func:`slamkit.scanmatch.normal_icp.normal_icp` against the reference scan as a one-scan
  :class:`~slamkit.scanmatch.point_map.PointMap`.

Published anchor (not run here): Censi's C implementation of PLICP (CSM) reports 8.7 ms per
180-beam match at 7.5 iterations on average (ICRA 2008).

The compiled kernels are loaded (or compiled) by one warm-up match before any timing; the
time of a cold compile is measured separately, in a child process with an empty numba cache.

Run: ``python benchmarks/bench_scanmatch.py``, in the environment a user has (no thread
variables): the matchers are timed as a Python caller gets them, with BLAS's own thread
count, and Open3D with its own OpenMP threads; the notes record both.
"""

from __future__ import annotations

import contextlib
import math
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from _common import Record, write_results
from slamkit.backend import AVAILABLE, SEAM, Backend
from slamkit.datasets import find_data_root, load_dataset
from slamkit.datasets.stream import LaserScan
from slamkit.errors import DataNotFoundError, MatchError
from slamkit.geometry.pose2 import between, compose
from slamkit.runtime import blas_thread_counts
from slamkit.scanmatch import correlative_match, icp, plicp, scan_points
from slamkit.scanmatch.normal_icp import normal_icp
from slamkit.scanmatch.point_map import PointMap
from slamkit.sim import random_scan_pairs, rooms_world

try:  # Open3D is an optional peer: the benchmark runs without it
    import open3d as o3d
except ImportError:  # pragma: no cover - depends on the environment
    o3d = None

BEAMS = np.linspace(-np.pi / 2, np.pi / 2, 180)
SIM_OFFSETS = ((0.1, 3.0), (0.3, 10.0), (0.5, 20.0))  # (metres, degrees)
REAL_OFFSETS = ((0.1, 3.0), (0.3, 10.0))
SIM_SUCCESS = (0.05, math.radians(1.0))
REAL_SUCCESS = (0.10, math.radians(2.0))
MAX_DIST = 1.0

Pose = np.ndarray
Matcher = Callable[[np.ndarray, np.ndarray, Pose], Pose]


@dataclass
class Pair:
    reference: np.ndarray
    current: np.ndarray
    truth: Pose


# --- the NumPy peer --------------------------------------------------------------------------


def numpy_icp(ref: np.ndarray, cur: np.ndarray, init: Pose) -> Pose:
    """Point-to-point ICP with brute-force nearest neighbours, trimmed to the best 90%."""
    tx, ty, th = (float(v) for v in init)
    ref_sq = np.einsum("ij,ij->i", ref, ref)
    for _ in range(100):
        c, s = math.cos(th), math.sin(th)
        moved = cur @ np.array([[c, s], [-s, c]]) + (tx, ty)
        d2 = np.einsum("ij,ij->i", moved, moved)[:, None] + ref_sq[None, :] - 2.0 * moved @ ref.T
        j = np.argmin(d2, axis=1)
        dist = np.sqrt(np.maximum(d2[np.arange(cur.shape[0]), j], 0.0))
        ok = dist < MAX_DIST
        if np.count_nonzero(ok) < 10:
            raise MatchError("numpy-icp: too few correspondences", "too_few_correspondences")
        cut = np.quantile(dist[ok], 0.9)
        ok &= dist <= cut
        q, p = cur[ok], ref[j[ok]]
        qm, pm = q.mean(axis=0), p.mean(axis=0)
        qc, pc = q - qm, p - pm
        new_th = math.atan2(
            float(np.sum(qc[:, 0] * pc[:, 1] - qc[:, 1] * pc[:, 0])), float(np.sum(qc * pc))
        )
        c, s = math.cos(new_th), math.sin(new_th)
        new_t = pm - np.array([c * qm[0] - s * qm[1], s * qm[0] + c * qm[1]])
        step = math.hypot(new_t[0] - tx, new_t[1] - ty)
        dth = abs(math.remainder(new_th - th, 2 * math.pi))
        tx, ty, th = float(new_t[0]), float(new_t[1]), new_th
        if step < 1e-4 and dth < 1e-4:
            return np.array([tx, ty, th])
    raise MatchError("numpy-icp: no convergence", "no_convergence")


# --- the Open3D peers ------------------------------------------------------------------------


def _matrix(pose: Pose) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:2, 3] = pose[:2]
    return m


def _cloud(points: np.ndarray):
    xyz = np.column_stack([points, np.zeros(points.shape[0])])
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))


def _pose(matrix: np.ndarray) -> Pose:
    return np.array([matrix[0, 3], matrix[1, 3], math.atan2(matrix[1, 0], matrix[0, 0])])


def open3d_p2p(ref: np.ndarray, cur: np.ndarray, init: Pose) -> Pose:
    reg = o3d.pipelines.registration
    result = reg.registration_icp(
        _cloud(cur),
        _cloud(ref),
        MAX_DIST,
        _matrix(init),
        reg.TransformationEstimationPointToPoint(),
        reg.ICPConvergenceCriteria(max_iteration=100),
    )
    return _pose(result.transformation)


def open3d_p2plane(ref: np.ndarray, cur: np.ndarray, init: Pose) -> Pose:
    reg = o3d.pipelines.registration
    n = ref.shape[0]
    # Normals of a flat cloud all point along z; estimate them on a copy extruded to
    # z = -0.05, 0, +0.05 m (a wall of the same plan), keep the middle layer's, and drop their
    # z part (a tilted normal couples in roll and pitch, which 2D points cannot fix).
    layers = np.vstack([np.column_stack([ref, np.full(n, z)]) for z in (-0.05, 0.0, 0.05)])
    wall = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(layers))
    wall.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=15))
    normals = np.asarray(wall.normals)[n : 2 * n].copy()
    normals[:, 2] = 0.0
    normals /= np.maximum(np.linalg.norm(normals, axis=1), 1e-12)[:, None]
    target = _cloud(ref)
    target.normals = o3d.utility.Vector3dVector(normals)
    result = reg.registration_icp(
        _cloud(cur),
        target,
        MAX_DIST,
        _matrix(init),
        reg.TransformationEstimationPointToPlane(),
        reg.ICPConvergenceCriteria(max_iteration=100),
    )
    return _pose(result.transformation)


# --- the runs --------------------------------------------------------------------------------


def plicp_numpy(ref: np.ndarray, cur: np.ndarray, init: Pose) -> Pose:
    with SEAM.use(Backend.NUMPY):
        return plicp(ref, cur, init).pose


def normal_icp_of_scan(ref: np.ndarray, cur: np.ndarray, init: Pose) -> Pose:
    cloud = PointMap(0.05)
    cloud.insert(np.zeros(3), ref)
    return normal_icp(cloud.near(np.zeros(2), 100.0), cur, init).pose


def _methods() -> dict[str, Matcher]:
    methods: dict[str, Matcher] = {
        "plicp": lambda r, c, x: plicp(r, c, x).pose,
        "plicp-numpy": plicp_numpy,
        "icp": lambda r, c, x: icp(r, c, x).pose,
        "numpy-icp": numpy_icp,
        # slamkit's other matchers on the same pairs (not peers: their rows show what each
        # costs and how far it reaches): Olson's correlative search over ±0.5 m / ±20°
        # (the reference rasterised in each call), and point-to-normal ICP against the
        # reference scan as a one-scan point map.
        "correlative": lambda r, c, x: correlative_match(r, c, x).pose,
        "normal-icp": normal_icp_of_scan,
    }
    if o3d is not None:
        methods["open3d-p2p"] = open3d_p2p
        methods["open3d-p2plane"] = open3d_p2plane
    return methods


def _offsets(n: int, size: tuple[float, float], rng: np.random.Generator) -> np.ndarray:
    direction = rng.uniform(-np.pi, np.pi, n)
    sign = np.where(rng.random(n) < 0.5, -1.0, 1.0)
    return np.column_stack(
        [size[0] * np.cos(direction), size[0] * np.sin(direction), sign * math.radians(size[1])]
    )


def _run_all(
    methods: dict[str, Matcher], pairs: list[Pair], inits: np.ndarray, repeats: int
) -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
    """Per method: the mean over the pairs of the best of ``repeats`` wall times of one match
    (the methods take turns on each pair, so a change of machine load hits all of them), the
    errors ``(n, 2)`` (m, rad; NaN when it raised) and a mask of the refusals
    (``MatchError``)."""
    total = dict.fromkeys(methods, 0.0)
    errors = {name: np.full((len(pairs), 2), np.nan) for name in methods}
    refused = {name: np.zeros(len(pairs), dtype=bool) for name in methods}
    for k, (pair, init) in enumerate(zip(pairs, inits, strict=True)):
        for name, fn in methods.items():
            best = float("inf")
            for _ in range(repeats):
                start = time.perf_counter()
                try:
                    pose = fn(pair.reference, pair.current, init)
                except MatchError:
                    pose = None
                best = min(best, time.perf_counter() - start)
            total[name] += best
            if pose is None:
                refused[name][k] = True
                continue
            e = between(pair.truth, pose)
            errors[name][k] = (math.hypot(e[0], e[1]), abs(e[2]))
    return {name: (total[name] / len(pairs), errors[name], refused[name]) for name in methods}


def _iterations(pairs: list[Pair], inits: np.ndarray) -> dict[str, float]:
    out = {}
    for name, fn in (("plicp", plicp), ("icp", icp)):
        # plicp-numpy takes the same iterations (the paths agree to rounding; a test checks)
        its = []
        for pair, init in zip(pairs, inits, strict=True):
            with contextlib.suppress(MatchError):
                its.append(fn(pair.reference, pair.current, init).iterations)
        out[name] = float(np.mean(its)) if its else float("nan")
    out["plicp-numpy"] = out["plicp"]
    return out


def _version(package: str) -> str:
    from importlib.metadata import version

    return version(package)


def _sim_pairs(n: int, seed: int) -> list[Pair]:
    sims = random_scan_pairs(
        rooms_world(),
        n,
        np.random.default_rng(seed),
        beam_angles=BEAMS,
        max_range=20.0,
        range_sigma=0.01,
    )
    return [Pair(p.reference, p.current, p.T_ref_cur) for p in sims]


def _intel_pairs(step: int) -> tuple[list[Pair], str]:
    if find_data_root() is None:
        return [], "real pairs skipped: SLAMKIT_DATA (the shared data folder) not found"
    try:
        data = load_dataset("intel")
    except DataNotFoundError as exc:
        return [], f"real pairs skipped: {exc}"
    assert data.laser is not None and data.truth is not None and data.truth.poses is not None
    scans = [ev for ev in data.events if isinstance(ev, LaserScan)]
    truth = data.truth.poses
    angles, rmax = data.laser.beam_angles, data.laser.max_range
    points = [scan_points(s.ranges, angles, rmax) for s in scans]
    pairs = [
        Pair(points[k], points[k + 1], between(truth[k], truth[k + 1]))
        for k in range(0, len(scans) - 1, step)
    ]
    return pairs, f"{len(pairs)} consecutive Intel pairs (every {step}th of {len(scans) - 1})"


def _evaluate(
    label: str,
    pairs: list[Pair],
    offsets: tuple[tuple[float, float], ...],
    success: tuple[float, float],
    repeats: int,
    seed: int,
) -> tuple[list[str], list[Record], dict[str, float]]:
    rows, records = [], []
    times_at_main: dict[str, float] = {}
    for size in offsets:
        rng = np.random.default_rng(seed)
        inits = compose(np.array([p.truth for p in pairs]), _offsets(len(pairs), size, rng))
        its = _iterations(pairs, inits)
        runs = _run_all(_methods(), pairs, inits, repeats)
        times = {name: run[0] for name, run in runs.items()}
        for name, (t, err, refused) in runs.items():
            ok = (err[:, 0] < success[0]) & (err[:, 1] < success[1])
            wrong = ~ok & ~refused
            good = err[ok]
            med_t = float(np.median(good[:, 0])) * 100 if good.size else float("nan")
            med_r = float(np.degrees(np.median(good[:, 1]))) if good.size else float("nan")
            rows.append(
                f"| {label} | {size[0]:g} m, {size[1]:g}° | {name} | {100 * ok.mean():.1f}% "
                f"| {100 * refused.mean():.1f}% | {100 * wrong.mean():.1f}% "
                f"| {med_t:.2f} | {med_r:.3f} | {1e3 * t:.3f} "
                f"| {its.get(name, float('nan')):.1f} |"
            )
        for peer in ("plicp-numpy", "icp", "numpy-icp", "open3d-p2p", "open3d-p2plane"):
            if peer in times:
                records.append(
                    Record(
                        f"{label}, offset {size[0]:g} m / {size[1]:g}°: plicp per match",
                        times["plicp"],
                        peer,
                        times[peer],
                    )
                )
        if size == (0.3, 10.0):
            times_at_main = times
    return rows, records, times_at_main


_COMPILE_SCRIPT = textwrap.dedent(
    """
    import time
    import numpy as np
    from slamkit.backend import SEAM
    from slamkit.scanmatch import plicp
    a = np.linspace(-np.pi / 2, np.pi / 2, 180)
    ref = np.column_stack([4.0 * np.cos(a), 3.0 + 0.5 * np.sin(3 * a)])
    start = time.perf_counter()
    plicp(ref, ref, (0.05, -0.03, 0.02))
    print(SEAM.backend.value, time.perf_counter() - start)
    """
)


def _compile_seconds() -> tuple[float, float]:
    """Seconds of the first match in a fresh process: with an empty numba cache (a cold
    compile of every kernel) and then with the cache it wrote (loading only)."""
    times = []
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for _ in range(2):
            out = subprocess.run(
                [sys.executable, "-c", _COMPILE_SCRIPT],
                capture_output=True,
                text=True,
                env=env,
                check=True,
            ).stdout.split()
            times.append(float(out[1]) if out[0] == "numba" else float("nan"))
    return times[0], times[1]


def _warm_up() -> float:
    """Load (or compile) the kernels with one match, before anything is timed."""
    pair = _sim_pairs(1, 99)[0]
    start = time.perf_counter()
    with contextlib.suppress(MatchError):
        plicp(pair.reference, pair.current, pair.truth)
    return time.perf_counter() - start


def main(n_sim: int = 50, real_step: int = 2, repeats: int = 7, seed: int = 0) -> str:
    cold, cached = _compile_seconds() if AVAILABLE else (float("nan"), float("nan"))
    warm_up = _warm_up()
    load_before = os.getloadavg()[0]
    header = [
        "| pairs | initial offset | method | success | refused | returned wrong "
        "| median error [cm] | median error [°] | ms per match | mean iterations |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    sim_pairs = _sim_pairs(n_sim, seed)
    rows, records, sim_times = _evaluate(
        f"sim ({n_sim})", sim_pairs, SIM_OFFSETS, SIM_SUCCESS, repeats, seed
    )
    real_pairs, real_note = _intel_pairs(real_step)
    if real_pairs:
        real_rows, real_records, _ = _evaluate(
            "Intel", real_pairs, REAL_OFFSETS, REAL_SUCCESS, max(1, repeats // 2), seed
        )
        rows += real_rows
        records += real_records
    else:
        print(real_note)
    ratios = ", ".join(
        f"{name} {sim_times[name] / sim_times['plicp']:.2f}×"
        for name in sim_times
        if name != "plicp"
    )
    env = {
        k: os.environ.get(k, "unset")
        for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")
    }
    if AVAILABLE:
        numba_note = (
            f"numba {_version('numba')}: plicp runs the compiled kernels, plicp-numpy the NumPy "
            f"path. Compiling every kernel in a fresh process with an empty cache took "
            f"{cold:.1f} s, loading them from the cache {cached:.2f} s (the first match of a "
            f"process); the warm-up match of this run took {warm_up:.2f} s; none of it is in "
            "the times above."
        )
    else:
        numba_note = "numba absent: plicp and plicp-numpy both run the NumPy path."
    notes = "\n".join(
        [
            "Scan-to-scan matching, 180-beam scans. Success: no MatchError and within "
            "5 cm / 1° of the truth (simulated) or 10 cm / 2° of the corrected-log motion "
            "(Intel); refused: the matcher raised MatchError (slamkit's matchers refuse "
            "degenerate geometry, e.g. Intel's corridors; the peers never refuse); returned "
            "wrong: a pose outside those bounds. Median errors over the successful matches. "
            f"Time per match: the best of {repeats} calls ({max(1, repeats // 2)} on Intel) "
            "per pair, averaged over the "
            "pairs; the methods take turns on each pair; everything from the two point "
            "arrays (trees, normals) included. Mean iterations only for slamkit's matchers "
            "(Open3D does not report them).",
            "",
            *header,
            *rows,
            "",
            f"Simulated pairs at 0.3 m / 10° offset, time per match relative to plicp: {ratios}.",
            numba_note,
            f"Real data: {real_note}.",
            "Published anchor, not run here: Censi's C implementation of PLICP (CSM), "
            "8.7 ms per 180-beam match at 7.5 iterations (ICRA 2008, on the hardware of the "
            "time).",
            f"Threads: BLAS {blas_thread_counts()}, thread variables {env}; Open3D "
            f"{'absent' if o3d is None else o3d.__version__}. "
            f"Machine load average (1 min) {load_before:.2f} before, "
            f"{os.getloadavg()[0]:.2f} after the run: the machine is shared, so compare "
            "the ratios within a run, not absolute times across runs.",
        ]
    )
    return write_results("scanmatch", records, notes=notes)


if __name__ == "__main__":
    print(main())
