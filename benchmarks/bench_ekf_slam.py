"""EKF-SLAM update cost against the size of the map, and the memory traffic it implies.

One measurement update of EKF-SLAM with ``L`` landmarks (``n = 3 + 2L`` states) must touch
the whole ``n × n`` covariance: every entry changes (the robot correlates every landmark with
every other). The arithmetic is a rank-4 correction, a few flops per entry, so the update is
bound by memory traffic: at best the matrix is read once and written once, ``16 n²`` bytes.
This script measures, for ``L`` = 100, 250, 500, 1000, 2000:

* slamkit's update (``slamkit.slam.ekf_slam.update.update_inplace``, the kernel the estimator runs
  per reading): ``H Σ`` from five rows, the gain, and the Joseph form as one rank-4 product
  applied in cache-sized blocks of rows;
* the peer, a plain NumPy EKF update with the dense ``2 × n`` Jacobian:
  ``P Hᵀ = Σ @ H.T``, ``S``, ``K = P Hᵀ S⁻¹``, ``Σ -= K @ S @ K.T`` (the short form, with an
  ``n × n`` temporary);
* a streaming reference: ``np.multiply(Σ, c, out=Σ)``, which reads and writes the matrix once
  and nothing else — the bandwidth ceiling of an in-place pass on this machine.

Each is reported as seconds per update, nanoseconds per matrix entry (the constant of the
``O(n²)``) and the effective bandwidth ``16 n² / t``. Both updates are applied, repeatedly,
to the same matrices and state; before timing, one update of each from the same state is
compared (they agree to 1e-12 relative: Joseph and short form differ only by rounding).

Second part, EKF-SLAM against SEIF as the map grows: one run along a 1 km road lined with
1000 landmarks (one per metre, alternating sides, 2–4 m off the road; 6 m range, so ~12
readings per scan; 0.5 s steps at 2 m/s; known ids), timing every step (one control and one
scan) of slamkit's ``EkfSlam`` and ``Seif`` (``max_active = 6``), reported at the steps when
the map holds about 100, 250, 500 and 1000 landmarks (median of the steps within ±5 %), with
the accuracy of both at the end (position RMSE along the run, map error after a rigid
alignment; SEIF's map from its exact mean, Ω⁻¹ξ, solved once at the end).

Run: ``python benchmarks/bench_ekf_slam.py`` or ``python benchmarks/run.py ekf_slam``.
"""

from __future__ import annotations

import time
from functools import partial

import numpy as np

from _common import Record, best_of, write_results
from slamkit.datasets import Dataset, LandmarkReadings
from slamkit.eval import landmark_map_error, pose_errors
from slamkit.maps import LandmarkMap
from slamkit.models import RangeBearing
from slamkit.runtime import blas_thread_counts, blas_threads
from slamkit.sim.scenarios import LandmarkScenarioConfig, landmark_dataset
from slamkit.slam import EkfSlam, EkfSlamConfig, Seif, SeifConfig
from slamkit.slam.ekf_slam.update import SCRATCH_BYTES, update_inplace

SIZES = (100, 250, 500, 1000, 2000)
R = np.diag([0.1**2, np.deg2rad(2.0) ** 2])


def make_state(L: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A SLAM state with ``L`` landmarks within 20 m and a dense, fully correlated
    covariance (rank-40 plus a diagonal)."""
    rng = np.random.default_rng(seed)
    n = 3 + 2 * L
    mean = np.concatenate([[0.0, 0.0, 0.1], rng.uniform(-20.0, 20.0, 2 * L)])
    A = rng.normal(size=(n, 40)) * 0.1
    cov = A @ A.T + 0.01 * np.eye(n)
    return mean, cov


def peer_update(mean: np.ndarray, cov: np.ndarray, j: int, z: np.ndarray) -> None:
    """The plain NumPy EKF update, in place: dense H, K = Σ Hᵀ S⁻¹, Σ -= K S Kᵀ."""
    model = RangeBearing()
    s = 3 + 2 * j
    Hr, Hj = model.jacobians(mean[:3], mean[s : s + 2])
    H = np.zeros((2, mean.size))
    H[:, :3], H[:, s : s + 2] = Hr, Hj
    nu = model.residual(z, model.predict(mean[:3], mean[s : s + 2]))
    PHt = cov @ H.T
    S = H @ PHt + R
    K = PHt @ np.linalg.inv(S)
    mean += K @ nu
    cov -= K @ S @ K.T


def subtract_ksk(cov: np.ndarray, K: np.ndarray, S: np.ndarray) -> None:
    """The covariance line of the peer alone, the gain given: ``Σ -= K S Kᵀ``."""
    cov -= K @ S @ K.T


def road_dataset(n_landmarks: int = 1000, seed: int = 0) -> Dataset:
    """A straight road with one landmark per metre, alternating sides, 2–4 m off it."""
    rng = np.random.default_rng(seed)
    k = np.arange(n_landmarks)
    x = k + rng.uniform(-0.3, 0.3, k.size) + 3.0
    y = np.where(k % 2, 1.0, -1.0) * rng.uniform(2.0, 4.0, k.size)
    world = LandmarkMap.from_positions(np.column_stack([x, y]))
    cfg = LandmarkScenarioConfig(dt=0.5, speed=2.0, max_range=6.0)
    end = np.array([[float(n_landmarks) + 6.0, 0.0]])
    return landmark_dataset("road", "", cfg, world, np.zeros(3), end, rng)


def growing_map(sizes: tuple[int, ...] = (100, 250, 500, 1000)) -> tuple[list[Record], str]:
    """EKF-SLAM and SEIF on one road run: step times at the given map sizes, accuracy."""
    dataset = road_dataset(max(sizes))
    assert dataset.truth.poses is not None and dataset.truth.landmarks is not None
    row = {t: i for i, t in enumerate(dataset.truth.times.tolist())}
    steps: dict[str, list[tuple[int, float]]] = {}
    accuracy: dict[str, tuple[float, float]] = {}
    for name, est in (
        ("ekf", EkfSlam(dataset, EkfSlamConfig(provisional_trace=None), np.random.default_rng(0))),
        ("seif", Seif(dataset, SeifConfig(), np.random.default_rng(0))),
    ):
        times, errors, tic = [], [], time.perf_counter()
        for ev in dataset.events:
            est.handle(ev)
            if isinstance(ev, LandmarkReadings):  # a step = the control before + this scan
                toc = time.perf_counter()
                times.append((len(est.landmark_ids), toc - tic))
                e = pose_errors(est.estimate().pose, dataset.truth.poses[row[ev.t]])
                errors.append(float(np.hypot(e[0], e[1])))
                tic = time.perf_counter()
        out = est.finish()
        assert out.landmarks is not None
        lm = landmark_map_error(out.landmarks.landmarks, dataset.truth.landmarks).rmse
        steps[name] = times
        accuracy[name] = (float(np.sqrt(np.mean(np.square(errors)))), lm)

    def at(name: str, L: int) -> float:
        sel = [t for n, t in steps[name] if abs(n - L) <= 0.05 * L]
        return float(np.median(sel))

    records = [
        Record(f"one step, {L} landmarks: SEIF", at("seif", L), "EKF-SLAM (slamkit)", at("ekf", L))
        for L in sizes
    ]
    lines = [
        "| landmarks | EKF-SLAM step [ms] | SEIF step [ms] | EKF / SEIF |",
        "|---:|---:|---:|---:|",
        *(
            f"| {L} | {at('ekf', L) * 1e3:.2f} | {at('seif', L) * 1e3:.2f} "
            f"| {at('ekf', L) / at('seif', L):.1f}× |"
            for L in sizes
        ),
        "",
        f"Accuracy at the end of the road: position RMSE EKF-SLAM {accuracy['ekf'][0]:.2f} m, "
        f"SEIF {accuracy['seif'][0]:.2f} m; map error after a rigid alignment EKF-SLAM "
        f"{accuracy['ekf'][1]:.2f} m, SEIF {accuracy['seif'][1]:.2f} m.",
    ]
    return records, "\n".join(lines)


def main() -> str:
    model = RangeBearing()
    records: list[Record] = []
    rows = []
    for L in SIZES:
        n = 3 + 2 * L
        j = L // 2
        mean, cov = make_state(L)
        z = model.predict(mean[:3], mean[3 + 2 * j : 5 + 2 * j]) + np.array([0.05, 0.01])
        scratch = np.empty(max(SCRATCH_BYTES // 8, n))

        # same answer from the same state
        m1, c1 = mean.copy(), cov.copy()
        update_inplace(m1, c1, 3 + 2 * j, z, model, R, (1,), scratch)
        m2, c2 = mean.copy(), cov.copy()
        peer_update(m2, c2, j, z)
        scale = float(np.abs(cov).max())
        assert np.abs(c1 - c2).max() < 1e-12 * scale, np.abs(c1 - c2).max()
        assert np.abs(m1 - m2).max() < 1e-10
        del m2, c2

        repeats = 9 if n < 2000 else 5
        ours = partial(update_inplace, m1, c1, 3 + 2 * j, z, model, R, (1,), scratch)
        t_ours, _ = best_of(ours, repeats=repeats)
        del m1, c1, ours
        m2, c2 = mean.copy(), cov.copy()
        t_peer, _ = best_of(partial(peer_update, m2, c2, j, z), repeats=repeats)
        del m2, c2
        K = np.random.default_rng(1).normal(size=(n, 2)) * 1e-3
        t_kskt, _ = best_of(partial(subtract_ksk, cov, K, np.eye(2)), repeats=repeats)
        t_stream, _ = best_of(partial(np.multiply, cov, 1.0 + 1e-12, out=cov), repeats=repeats)
        records.append(
            Record(
                f"one update, {L} landmarks (n = {n})",
                t_ours,
                "NumPy dense Σ -= K S Kᵀ",
                t_peer,
            )
        )
        rows.append((L, n, t_ours, t_peer, t_kskt, t_stream))

    # O(n²): the time per matrix entry should level off once the matrix leaves the caches
    lines = [
        "| landmarks | n | slamkit [ms] | ns / entry | GB/s | peer [ms] | ns / entry | GB/s "
        "| Σ -= K S Kᵀ only [ms] | GB/s | stream [ms] | stream GB/s | slamkit / stream |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for L, n, t_o, t_p, t_k, t_s in rows:
        b = 16.0 * n * n
        lines.append(
            f"| {L} | {n} | {t_o * 1e3:.3f} | {t_o / n**2 * 1e9:.2f} | {b / t_o / 1e9:.1f} "
            f"| {t_p * 1e3:.3f} | {t_p / n**2 * 1e9:.2f} | {b / t_p / 1e9:.1f} "
            f"| {t_k * 1e3:.3f} | {b / t_k / 1e9:.1f} "
            f"| {t_s * 1e3:.3f} | {b / t_s / 1e9:.1f} | {t_o / t_s:.1f}× |"
        )
    big = [r for r in rows if r[0] >= 500]
    n2 = np.array([r[1] ** 2 for r in big], dtype=float)
    c_ours = float(np.linalg.lstsq(n2[:, None], np.array([r[2] for r in big]), rcond=None)[0][0])
    c_peer = float(np.linalg.lstsq(n2[:, None], np.array([r[3] for r in big]), rcond=None)[0][0])
    notes = "\n".join(
        [
            "Seconds per EKF-SLAM measurement update (one range-bearing reading, the robot "
            "and one landmark in its Jacobian), best of 9 (5 for n > 2000) on a dense, fully "
            "correlated covariance; slamkit's kernel and the peer agree to 1e-12 of the "
            "largest entry. Bandwidth = 16 n² bytes (the matrix read and written once, the "
            "least an update can move) / time; 'stream' is np.multiply(Σ, c, out=Σ), one "
            "in-place pass and nothing else. slamkit forms the rank-4 Joseph correction in "
            f"blocks of rows of {SCRATCH_BYTES // 1024} KiB, so the matrix is streamed once; "
            "the peer writes an n × n temporary (K S Kᵀ, fresh pages every call) and reads "
            "it back ('Σ -= K S Kᵀ only' times that line alone, the gain given; the rest of "
            "the peer is Σ Hᵀ, one more read of Σ). Below ~500 landmarks the matrix fits in "
            "the caches and slamkit's fixed ~50 µs of Python per update shows. Both "
            "updates are called directly, in the environment the script was started in "
            f"(no thread variables needed): BLAS threads {blas_thread_counts()}.",
            "",
            *lines,
            "",
            f"Least-squares fit t = c n² over n ≥ 1003: slamkit c = {c_ours * 1e9:.2f} ns per "
            f"entry, peer c = {c_peer * 1e9:.2f} ns per entry.",
        ]
    )
    with blas_threads():  # stepped as slamkit run steps them: under the library's policy
        road_threads = blas_thread_counts()
        road_records, road_notes = growing_map()
    notes += (
        "\n\nEKF-SLAM against SEIF on one 1 km road run with 1000 landmarks (see the module "
        "docstring): wall time of one step (a control and a scan of ~12 readings) when the "
        "map holds about L landmarks; rows 'one step, L landmarks: SEIF' above (peer = "
        "EKF-SLAM). The estimators are stepped under slamkit.runtime.blas_threads(), the "
        f"policy slamkit run applies (BLAS threads {road_threads}).\n\n" + road_notes
    )
    return write_results("ekf_slam", records + road_records, notes=notes)


if __name__ == "__main__":
    print(main())
