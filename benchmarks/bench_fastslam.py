"""FastSLAM 1.0: slamkit's particle-vectorised filter against a per-particle Python loop of the
same algorithm, on the same simulated run; and the throughput on a long run with ~300
landmarks.

The run: a unicycle driving two laps of a 12 m × 8 m loop past 8 landmarks (range-bearing,
σ = 0.1 m / 2°, 6 m range, 0.3 m minimum range), 100 particles, dt = 0.1 s. A step is what
the filter does per control and scan: move every particle with its own control noise, process
the scan (per-particle association, landmark EKF updates and starts, existence counters), and
resample (low variance) when the effective sample size drops below half the particles. Two
cases: readings with landmark ids (known correspondences) and without (per-particle
maximum-likelihood association against every landmark of the particle, new-landmark threshold
``p0``).

slamkit: ``model.apply`` on the ``(P, 3)`` poses, :func:`~slamkit.slam.fastslam.fastslam1_update`
on the struct-of-arrays particle set, ``select(low_variance_resample(...))``.
Peer: the same algorithm written as one would first write it, per particle and per landmark:
a list of particles, each a pose and a list of landmarks holding a 2-vector and a 2×2 NumPy
covariance, ``math`` for the measurement model and NumPy for the 2×2 algebra (``@``,
``np.linalg.inv`` once per reading and landmark, shared by the likelihood and the update,
``np.linalg.det``). Both consume the same control noise and resampling offsets, drawn in the
same order from generators in the same state, and they must end with the same particles:
poses, weights and every landmark to 1e-9.

Timing: the run is cut into chunks of ``CHUNK_STEPS`` steps; each chunk is timed for slamkit
(best of ``repeats`` from copies of the same state) and right after it for the peer. The
machine is shared by other jobs and its speed drifts over seconds: timing the two side by side
keeps the ratio honest where two whole runs minutes apart would not. The notes record the
load average.

The long run: 300 random landmarks in a 100 m × 60 m field, a lawn-mower route of ~3000
steps; slamkit only (the loop would take hours), reported in steps per second, with the peer's
cost per step measured on a few steps from the same mid-run state.

Run: ``python benchmarks/bench_fastslam.py`` or ``python benchmarks/run.py fastslam``.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import time

import numpy as np

from _common import Record, write_results
from slamkit.datasets.stream import (
    Control,
    Dataset,
    Event,
    LandmarkReadings,
    LandmarkSensorSpec,
    MotionSpec,
)
from slamkit.maps import LandmarkMap
from slamkit.models import UnicycleEuler
from slamkit.sim import follow_waypoints, observe_landmarks, random_landmarks
from slamkit.slam.fastslam import FastSlam1, FastSlamConfig, FastSlamParticles, UpdateSettings

N_PARTICLES = 100
DT = 0.1
Q_U = np.diag([0.1**2, np.deg2rad(5.0) ** 2])
R = np.diag([0.1**2, np.deg2rad(2.0) ** 2])
_TWO_PI = 2.0 * math.pi


# --------------------------------------------------------------------------------------------
# The simulated runs
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass
class Run:
    dataset: Dataset
    controls: np.ndarray  # (T, 2)
    scans: list[tuple[np.ndarray, np.ndarray]]  # per step: z (K, 2), ids (K,)
    settings: UpdateSettings
    n_landmarks: int

    @property
    def readings_per_step(self) -> float:
        return sum(len(ids) for _, ids in self.scans) / len(self.scans)


def make_run(
    world: LandmarkMap,
    waypoints: np.ndarray,
    *,
    laps: int,
    max_range: float,
    identities: bool,
    seed: int,
) -> Run:
    rng = np.random.default_rng(seed)
    start = np.array([0.0, 0.0, 0.0])
    drive = follow_waypoints(
        start, waypoints, speed=1.0, dt=DT, laps=laps, control_cov=Q_U, rng=rng
    )
    sensor = LandmarkSensorSpec(
        "range-bearing", R, max_range=max_range, min_range=0.3, identities=identities
    )
    scans = [observe_landmarks(pose, world, sensor, rng) for pose in drive.poses[1:]]
    events: list[Event] = []
    for k, (z, ids) in enumerate(scans):
        t = (k + 1) * DT
        events.append(Control(t, drive.controls[k], DT))
        if ids.size:
            events.append(LandmarkReadings(t, z, ids))
    dataset = Dataset(
        "bench", tuple(events), motion=MotionSpec(UnicycleEuler(), Q_U),
        landmark_sensor=sensor, initial_pose=start, initial_cov=np.zeros((3, 3)),
    )  # fmt: skip
    est = FastSlam1(dataset, CONFIG, np.random.default_rng(0))
    return Run(dataset, drive.controls, scans, est.settings, len(world))


CONFIG = FastSlamConfig(n_particles=N_PARTICLES)
EIGHT = LandmarkMap.from_positions(
    [[2, -2], [7, -2.5], [12, -1], [14, 4], [11, 10], [5, 10.5], [-2, 9], [-2.5, 3]]
)
LOOP = np.array([[10.0, 0.0], [12.0, 4.0], [10.0, 8.0], [2.0, 8.0], [0.0, 4.0], [0.0, 0.0]])


def small_run(identities: bool, max_range: float) -> Run:
    return make_run(EIGHT, LOOP, laps=2, max_range=max_range, identities=identities, seed=3)


def long_run(identities: bool) -> Run:
    rng = np.random.default_rng(0)
    world = random_landmarks(rng, 300, (-5.0, -5.0, 105.0, 65.0), min_separation=2.0)
    rows = [(0.0, 0.0)]
    for i, y in enumerate(np.arange(0.0, 61.0, 12.0)):
        xs = (0.0, 100.0) if i % 2 == 0 else (100.0, 0.0)
        rows += [(xs[0], y), (xs[1], y)]
    return make_run(world, np.array(rows[1:]), laps=1, max_range=6.0, identities=identities,
                    seed=4)  # fmt: skip


# --------------------------------------------------------------------------------------------
# slamkit: the estimator, fed the events
# --------------------------------------------------------------------------------------------


def ours_start(run: Run, seed: int = 1) -> tuple[FastSlam1, np.random.Generator]:
    """The estimator, and a generator in the state the estimator's is in after its set-up
    (the peer draws from it the same numbers in the same order)."""
    rng = np.random.default_rng(seed)
    est = FastSlam1(run.dataset, CONFIG, rng)
    twin = np.random.Generator(type(rng.bit_generator)())
    twin.bit_generator.state = rng.bit_generator.state
    return est, twin


def ours_steps(est: FastSlam1, events: tuple[Event, ...]) -> FastSlam1:
    for ev in events:
        est.handle(ev)
    return est


# --------------------------------------------------------------------------------------------
# The peer: one particle and one landmark at a time
# --------------------------------------------------------------------------------------------


def _wrap(a: float) -> float:
    return (a + math.pi) % _TWO_PI - math.pi


class LoopFastSlam:
    """FastSLAM 1.0 per particle, per landmark: the textbook loops (Probabilistic Robotics,
    tables 13.1/13.2), with the same association order, counters and resampling as
    slamkit's, so the two can be checked against each other."""

    def __init__(self, s: UpdateSettings) -> None:
        self.s = s
        self.log_p0 = math.log(s.p0)
        self.next_id = s.first_unlabelled_id

    @staticmethod
    def from_particles(ps: FastSlamParticles) -> list[dict]:
        out = []
        for p in range(len(ps)):
            lms = [
                [int(ps.ids[p, j]), ps.means[p, j].copy(), ps.covs[p, j].copy(),
                 int(ps.counters[p, j])]
                for j in range(int(ps.counts[p]))
            ]  # fmt: skip
            out.append({"pose": ps.poses[p].tolist(), "logw": float(ps.log_weights[p]),
                        "lms": lms})  # fmt: skip
        return out

    @staticmethod
    def predict(parts: list[dict], u: np.ndarray, eps: np.ndarray, dt: float) -> None:
        for p, (ev, ew) in zip(parts, eps.tolist(), strict=True):
            x, y, th = p["pose"]
            v, w = u[0] + ev, u[1] + ew
            p["pose"] = [x + v * math.cos(th) * dt, y + v * math.sin(th) * dt,
                         _wrap(th + w * dt)]  # fmt: skip

    @staticmethod
    def _terms(pose, mu, cov, z):
        """Innovation, Jacobian, innovation covariance and its inverse (computed once, used
        by the likelihood and the update)."""
        dx, dy = mu[0] - pose[0], mu[1] - pose[1]
        q = dx * dx + dy * dy
        r = math.sqrt(q)
        nu = np.array([z[0] - r, _wrap(z[1] - _wrap(math.atan2(dy, dx) - pose[2]))])
        H = np.array([[dx / r, dy / r], [-dy / q, dx / q]])
        Q = H @ cov @ H.T + R
        return nu, H, Q, np.linalg.inv(Q)

    @staticmethod
    def _loglik(nu, H, Q, Q_inv):
        return -0.5 * float(nu @ Q_inv @ nu) - 0.5 * math.log(np.linalg.det(Q)) - math.log(_TWO_PI)

    @staticmethod
    def _ekf(lm, nu, H, Q, Q_inv):
        K = lm[2] @ H.T @ Q_inv
        lm[1] = lm[1] + K @ nu
        lm[2] = lm[2] - K @ H @ lm[2]
        lm[2] = 0.5 * (lm[2] + lm[2].T)

    @staticmethod
    def _new(pose, z, lid):
        a = pose[2] + z[1]
        c, s = math.cos(a), math.sin(a)
        Lz = np.array([[c, -z[0] * s], [s, z[0] * c]])
        return [lid, np.array([pose[0] + z[0] * c, pose[1] + z[0] * s]), Lz @ R @ Lz.T, 1]

    def update(self, parts: list[dict], z: np.ndarray, ids: np.ndarray) -> None:
        s = self.s
        order = [k for k in range(len(ids)) if ids[k] >= 0] + [
            k for k in range(len(ids)) if ids[k] < 0
        ]
        spawning = set()
        for p in parts:
            pose, lms = p["pose"], p["lms"]
            seen, updated, new_ids = set(), set(), 0
            for k in order:
                zk, rid = z[k], int(ids[k])
                if rid >= 0:
                    j = next((i for i, lm in enumerate(lms) if lm[0] == rid), -1)
                    if j >= 0:
                        t = self._terms(pose, lms[j][1], lms[j][2], zk)
                        p["logw"] += self._loglik(*t)
                        self._ekf(lms[j], *t)
                        seen.add(j)
                        updated.add(j)
                        continue
                    lid = rid
                else:
                    best, best_ll, best_t = -1, -math.inf, None
                    for j, lm in enumerate(lms):
                        if j in seen:
                            continue
                        t = self._terms(pose, lm[1], lm[2], zk)
                        ll = self._loglik(*t)
                        if ll > best_ll:
                            best, best_ll, best_t = j, ll, t
                    if best >= 0 and best_ll >= self.log_p0:
                        p["logw"] += best_ll
                        self._ekf(lms[best], *best_t)
                        seen.add(best)
                        updated.add(best)
                        continue
                    spawning.add(k)
                    lid = -1 - k  # the id is fixed once every particle has seen the scan
                    new_ids += 1
                p["logw"] += self.log_p0
                lms.append(self._new(pose, zk, lid))
                seen.add(len(lms) - 1)
            # existence counters, of the landmarks started by unlabelled readings
            for j, lm in enumerate(lms):
                if 0 <= lm[0] < s.first_unlabelled_id:
                    continue
                dx, dy = lm[1][0] - pose[0], lm[1][1] - pose[1]
                r = math.hypot(dx, dy)
                if j in updated:
                    lm[3] += 1
                elif j not in seen and s.visible_min_range <= r <= s.visible_max_range:
                    lm[3] -= 1
            p["lms"] = [lm for lm in lms if not (lm[3] < 0 and lm[0] >= s.first_unlabelled_id)]
        # ids of the landmarks the unlabelled readings started, in reading order
        ids_of = {k: self.next_id + i for i, k in enumerate(sorted(spawning))}
        self.next_id += len(spawning)
        for p in parts:
            for lm in p["lms"]:
                if lm[0] < 0 and s.first_unlabelled_id >= 0 and -1 - lm[0] in ids_of:
                    lm[0] = ids_of[-1 - lm[0]]
        m = max(p["logw"] for p in parts)
        total = m + math.log(sum(math.exp(p["logw"] - m) for p in parts))
        for p in parts:
            p["logw"] -= total

    @staticmethod
    def ess(parts: list[dict]) -> float:
        w = [math.exp(p["logw"]) for p in parts]
        total = sum(w)
        return 1.0 / sum((v / total) ** 2 for v in w)

    @staticmethod
    def resample(parts: list[dict], offset: float) -> list[dict]:
        w = [math.exp(p["logw"]) for p in parts]
        total = sum(w)
        n = len(w)
        out = []
        i, c = 0, w[0] / total
        for k in range(n):
            pointer = (offset + k) / n
            while pointer >= c and i < n - 1:
                i += 1
                c += w[i] / total
            src = parts[i]
            lms = [[lm[0], lm[1].copy(), lm[2].copy(), lm[3]] for lm in src["lms"]]
            out.append({"pose": list(src["pose"]), "logw": -math.log(n), "lms": lms})
        return out

    def run(
        self,
        parts: list[dict],
        events: tuple[Event, ...],
        rng: np.random.Generator,
        pending: bool = False,
    ) -> tuple[list[dict], bool]:
        """Feed the events, drawing from ``rng`` what the estimator draws, in its order:
        the resampling offset (when due) and the control noise at each control. Returns
        the particles and whether a resampling is due before the next motion."""
        lam, vec = np.linalg.eigh(Q_U)
        root = vec @ np.diag(np.sqrt(lam)) @ vec.T
        for ev in events:
            if isinstance(ev, Control):
                if pending:
                    parts = self.resample(parts, rng.random())
                    pending = False
                self.predict(parts, ev.u, rng.standard_normal((len(parts), 2)) @ root, ev.dt)
            elif isinstance(ev, LandmarkReadings):
                self.update(parts, ev.z, ev.ids)
                pending = self.ess(parts) < 0.5 * len(parts)
        return parts, pending


def check_same(ps: FastSlamParticles, parts: list[dict], tol: float = 1e-9) -> None:
    for i, p in enumerate(parts):
        if not np.allclose(ps.poses[i], p["pose"], rtol=0, atol=tol):
            raise AssertionError(f"particle {i}: poses differ")
        if abs(ps.log_weights[i] - p["logw"]) > tol * max(1.0, abs(p["logw"])):
            raise AssertionError(f"particle {i}: weights differ")
        if int(ps.counts[i]) != len(p["lms"]):
            raise AssertionError(f"particle {i}: {ps.counts[i]} vs {len(p['lms'])} landmarks")
        for j, lm in enumerate(p["lms"]):
            same = (
                ps.ids[i, j] == lm[0]
                and ps.counters[i, j] == lm[3]
                and np.allclose(ps.means[i, j], lm[1], rtol=0, atol=tol)
                and np.allclose(ps.covs[i, j], lm[2], rtol=0, atol=tol)
            )
            if not same:
                raise AssertionError(f"particle {i}, landmark {j}: differ")


# --------------------------------------------------------------------------------------------


CHUNK_STEPS = 50


def compare(run: Run, label: str, repeats: int) -> Record:
    """Both filters over the run in chunks of ``CHUNK_STEPS`` steps, each chunk timed for
    slamkit (best of ``repeats``, from copies of the same state) and then for the peer
    right after it: the machine is shared, and its speed drifts over seconds, so the two
    are timed side by side rather than one whole run after the other."""
    events = run.dataset.events
    est, twin = ours_start(run)
    loop = LoopFastSlam(run.settings)
    parts = loop.from_particles(est.particles)
    pending = False
    starts = [i for i, ev in enumerate(events) if isinstance(ev, Control)][::CHUNK_STEPS]
    t_ours = t_peer = 0.0
    for a, b in zip(starts, [*starts[1:], len(events)], strict=True):
        chunk = events[a:b]
        best = math.inf
        for _ in range(repeats):
            trial = copy.deepcopy(est)
            t0 = time.perf_counter()
            ours_steps(trial, chunk)
            best = min(best, time.perf_counter() - t0)
        est = trial  # every trial drew the same numbers: continue from the last one
        t_ours += best
        t0 = time.perf_counter()
        parts, pending = loop.run(parts, chunk, twin, pending)
        t_peer += time.perf_counter() - t0
    check_same(est.particles, parts)  # never benchmark a wrong answer
    n = len(run.scans)
    return Record(f"{label}: one step (mean of {n})", t_ours / n, "per-particle Python loop",
                  t_peer / n)  # fmt: skip


def long_run_rate(identities: bool, peer_steps: int) -> tuple[Record, str]:
    run = long_run(identities)
    events = run.dataset.events
    n = len(run.scans)
    controls = [i for i, ev in enumerate(events) if isinstance(ev, Control)]
    mid = controls[n // 2]  # the window starts at a control
    end = controls[n // 2 + peer_steps]
    est, _ = ours_start(run)
    t0 = time.perf_counter()
    ours_steps(est, events[:mid])
    t_first = time.perf_counter() - t0
    half = copy.deepcopy(est)
    t0 = time.perf_counter()
    ours_steps(est, events[mid:])
    t_total = t_first + time.perf_counter() - t0
    window = events[mid:end]
    loop = LoopFastSlam(run.settings)
    loop.next_id = half.particles.next_id
    twin = copy.deepcopy(half).generator  # the estimator's generator, in its mid-run state
    start = loop.from_particles(half.particles)
    t0 = time.perf_counter()
    theirs, _ = loop.run(start, window, twin, half.resample_pending)
    t_peer = (time.perf_counter() - t0) / peer_steps
    check_same(ours_steps(copy.deepcopy(half), window).particles, theirs)
    t_window = math.inf
    for _ in range(5):  # copies made outside the timing (the estimator carries its history)
        trial = copy.deepcopy(half)
        t0 = time.perf_counter()
        ours_steps(trial, window)
        t_window = min(t_window, time.perf_counter() - t0)
    label = "ids" if identities else "unknown association"
    ps = est.particles
    note = (
        f"Long run, {label}: {n} steps, {run.n_landmarks} landmarks in the world, "
        f"{run.readings_per_step:.1f} readings per step, {int(ps.counts.max())} landmarks in "
        f"the largest map at the end; {n / t_total:.0f} steps/s over the whole run."
    )
    rec = Record(f"long run (~300 landmarks), {label}: one step mid-run (mean of "
                 f"{peer_steps})", t_window / peer_steps, "per-particle Python loop",
                 t_peer)  # fmt: skip
    return rec, note


def main(repeats: int = 5) -> str:
    dense = [small_run(ids, 12.0) for ids in (True, False)]
    sparse = [small_run(ids, 6.0) for ids in (True, False)]
    records = [
        compare(dense[0], "8 landmarks in view, ids", repeats),
        compare(dense[1], "8 landmarks in view, unknown association", repeats),
        compare(sparse[0], "8 landmarks, 6 m range, ids", repeats),
        compare(sparse[1], "8 landmarks, 6 m range, unknown association", repeats),
    ]
    notes = []
    for identities, peer_steps in ((True, 10), (False, 3)):
        rec, note = long_run_rate(identities, peer_steps)
        records.append(rec)
        notes.append(note)
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    text = (
        f"Load average (1, 5, 15 min) at the end: {load} on {os.cpu_count()} CPUs. "
        f"FastSLAM 1.0 (the `fastslam1` estimator fed the events), {N_PARTICLES} particles. "
        f"Short runs: {len(dense[0].scans)} steps around 8 landmarks, 12 m range "
        f"({dense[0].readings_per_step:.1f} readings per step) and 6 m range "
        f"({sparse[0].readings_per_step:.1f} readings per step). A step is a control (motion "
        "of every particle) and a scan (association, landmark EKFs, existence counters, "
        "resampling when ESS < P/2). The two are timed side by side in chunks of "
        f"{CHUNK_STEPS} steps with the same random numbers and must end with the same "
        "particles (poses, weights, every landmark to 1e-9). " + " ".join(notes)
    )
    return write_results("fastslam", records, notes=text)


if __name__ == "__main__":
    print(main())
