"""A stated, seeded model of wheel-odometry errors, applied to any data set with a true path.

:func:`corrupt_odometry` rebuilds a data set's :class:`~slamkit.datasets.Odometry` events
from its true poses with the errors of an :class:`OdometryErrorModel`, so that the same
error model can be put on simulated buildings (:mod:`slamkit.sim.buildings`) and on real logs
whose poses are known (the corrected CARMEN logs), and an estimator is judged against
odometry whose faults are known and listed.

The model, per odometry step ``k`` (from reading ``k - 1`` to reading ``k``), on the true
increment ``(rot1, trans, rot2)`` (:func:`~slamkit.models.odometry_control`), true
distance ``d = trans`` and true turn ``a = rot1 + rot2``:

1. **Systematic errors of a differential drive.** The wheels roll ``d_L``, ``d_R``; the
   odometry computes ``d = (d_R + d_L) / 2`` and ``a = (d_R - d_L) / b``. A wheel-radius
   error ``ε_r`` (both radii assumed ``1 + ε_r`` times too large) scales both reported wheel
   distances by ``1 + ε_r``; a wheel-base error ``ε_b`` (base assumed ``(1 + ε_b) b``)
   divides the turn by ``1 + ε_b``. Hence::

       d' = (1 + ε_r) d,        a' = (1 + ε_r) / (1 + ε_b) · a = s · a,

   applied as ``trans' = (1 + ε_r) trans``, ``rot1' = s rot1``, ``rot2' = s rot2``. This is
   exact for straight steps and turns on the spot; on an arc the reported chord differs from
   ``(1 + ε_r)`` times the true one by a relative ``(a² / 24) |1 - s²|`` (1e-4 for a 0.2 rad
   step with ``s = 1.03``), which is neglected.
2. **Random errors**, independent per step, from slip that accumulates with the distance
   rolled and the angle turned (variances add, so each is a random walk)::

       e_trans ~ N(0, k_trans² · d),      e_turn ~ N(0, k_rot² · |a| + k_drift² · d),

   ``trans' += e_trans``, and ``e_turn`` is split evenly, ``rot1' += e_turn / 2``,
   ``rot2' += e_turn / 2`` (the heading error of a step arises along it).
3. **Glitches**, rare, drawn per step (rates per odometry step; see
   :class:`OdometryGlitch` for what each records):

   * ``heading_jump``: ``rot2' += J``, ``|J| ~ U(30°, 90°)``, random sign — a gyro or encoder
     fault; the odometry carries the wrong heading on from then;
   * ``stall``: for ``L ~ U{3..10}`` steps the increments are zero — the wheels stop
     reporting while the laser moves on; the motion of those steps is lost;
   * ``duplicate``: reading ``k`` appears twice at the same stamp (same pose) — a driver that
     published one message twice, as a reader passes it on;
   * ``out_of_order``: the raw stamp of reading ``k`` lay ``δ ~ U(0.05, 1) s`` before that
     of reading ``k - 1``; a reader keeps the file order and repairs the stamp to
     ``t_{k-1} + 1 ms`` (as :mod:`slamkit.datasets.carmen` does), so the data set holds
     reading ``k`` (its pose right) at that repaired stamp. The raw stamp is reported.

The data set requires non-decreasing stamps, so duplicated and out-of-order stamps appear
as a reader would show them after repair; the glitch list keeps the raw facts.

The odometry starts at the true pose of the first stamp (the odometry frame is the world
frame there), as the CARMEN reader's does. The returned :class:`~slamkit.datasets.MotionSpec`
is the :class:`~slamkit.models.OdometryModel` with the nominal covariance of
:meth:`OdometryErrorModel.nominal_cov`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any, ClassVar, Literal

import numpy as np

from slamkit._validation import FloatArray
from slamkit.config import Section, config_to_dict, finite_at_least, optional, setting
from slamkit.datasets.assemble import assemble_events
from slamkit.datasets.stream import Control, Dataset, Event, LaserScan, MotionSpec, Odometry
from slamkit.errors import InputError
from slamkit.geometry import wrap_angle
from slamkit.geometry.pose2 import interpolate_poses
from slamkit.models import (
    OdometryModel,
    integrate_odometry,
    odometry_control,
    signed_odometry_steps,
)

__all__ = [
    "GlitchKind",
    "OdometryErrorModel",
    "OdometryGlitch",
    "OdometryGlitches",
    "corrupt_odometry",
]

GlitchKind = Literal["heading_jump", "stall", "duplicate", "out_of_order"]

STAMP_REPAIR_STEP = 1e-3
"""[s] after the previous stamp where a reader puts a reading whose stamp was out of order."""


def _range_check(low: float, high: float) -> Any:
    """A pair ``(lo, hi)`` with ``low <= lo <= hi <= high``."""

    def check(v: Any) -> bool:
        try:
            lo, hi = (float(x) for x in v)
        except (TypeError, ValueError):
            return False
        return bool(low <= lo <= hi <= high)

    return check


_RATE = "a probability per step in [0, 1]"


def _rate_check(v: Any) -> bool:
    return bool(finite_at_least(0.0)(v) and v <= 1.0)


@dataclass(frozen=True)
class OdometryErrorModel(Section):
    """The errors :func:`corrupt_odometry` puts on odometry (the equations are in the module
    docstring). The defaults are the corpus's "typical" model: about 1 % random translation
    error over 10 m, a few degrees of heading random walk per 100 m, systematic errors of
    1-3 %, and glitch rates giving 2 glitches in a 500-step log on average (Poisson; 1-3
    glitches in 72 % of such logs)."""

    SECTION: ClassVar[str] = "odometry_errors"

    k_trans: float = setting(0.01, finite_at_least(0.0), "a number >= 0 [m/√m]")
    """Random translation error [m/√m]: per step σ = k_trans·√d (1 cm after 1 m, 3 cm after
    10 m of travel)."""
    k_rot: float = setting(0.03, finite_at_least(0.0), "a number >= 0 [rad/√rad]")
    """Random turn error from turning [rad/√rad]: variance k_rot²·|a| per step (4.3° after a
    full turn)."""
    k_drift: float = setting(0.005, finite_at_least(0.0), "a number >= 0 [rad/√m]")
    """Random heading drift while driving [rad/√m]: variance k_drift²·d per step (2.9° after
    100 m)."""
    wheel_radius_error: float | None = setting(
        None, optional(lambda v: finite_at_least(-0.5)(v) and v <= 0.5), "None or in [-0.5, 0.5]"
    )
    """ε_r: relative error of the wheel radii; None draws ``±U(systematic_range)``."""
    wheel_base_error: float | None = setting(
        None, optional(lambda v: finite_at_least(-0.5)(v) and v <= 0.5), "None or in [-0.5, 0.5]"
    )
    """ε_b: relative error of the wheel base; None draws ``±U(systematic_range)``."""
    systematic_range: tuple[float, float] = setting(
        (0.01, 0.03), _range_check(0.0, 0.5), "a pair 0 <= lo <= hi <= 0.5"
    )
    """Magnitude range of the drawn ε_r and ε_b (uniform; the sign is drawn too)."""
    heading_jump_rate: float = setting(0.001, _rate_check, _RATE)
    """Probability per step of a heading jump."""
    heading_jump_deg: tuple[float, float] = setting(
        (30.0, 90.0), _range_check(0.0, 180.0), "a pair 0 <= lo <= hi <= 180 [deg]"
    )
    """Magnitude range of a heading jump [deg] (uniform, random sign)."""
    stall_rate: float = setting(0.001, _rate_check, _RATE)
    """Probability per step that a stall starts."""
    stall_steps: tuple[int, int] = setting(
        (3, 10), _range_check(1, 1_000_000), "a pair 1 <= lo <= hi of step counts"
    )
    """Length range of a stall [steps] (uniform integers, both ends included)."""
    duplicate_rate: float = setting(0.001, _rate_check, _RATE)
    """Probability per reading of being published twice."""
    out_of_order_rate: float = setting(0.001, _rate_check, _RATE)
    """Probability per reading of a raw stamp earlier than its predecessor's."""
    out_of_order_lag: tuple[float, float] = setting(
        (0.05, 1.0), _range_check(0.0, math.inf), "a pair 0 <= lo <= hi [s]"
    )
    """How far [s] before its predecessor's stamp the raw stamp lies (uniform)."""

    @classmethod
    def exact(
        cls, wheel_radius_error: float = 0.0, wheel_base_error: float = 0.0
    ) -> OdometryErrorModel:
        """Only the given systematic errors: no random noise, no glitches."""
        return cls(
            k_trans=0.0, k_rot=0.0, k_drift=0.0, wheel_radius_error=wheel_radius_error,
            wheel_base_error=wheel_base_error, heading_jump_rate=0.0, stall_rate=0.0,
            duplicate_rate=0.0, out_of_order_rate=0.0,
        )  # fmt: skip

    def without_glitches(self) -> OdometryErrorModel:
        """This model with every glitch rate zero."""
        return replace(
            self, heading_jump_rate=0.0, stall_rate=0.0, duplicate_rate=0.0, out_of_order_rate=0.0
        )

    def step_sigmas(self, trans: FloatArray, turn: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Standard deviations ``(σ_trans, σ_turn)`` of the random error of steps with true
        distances ``trans`` [m] and turns ``turn`` [rad] (arrays of one shape)."""
        d = np.abs(trans)
        sigma_t = self.k_trans * np.sqrt(d)
        sigma_a = np.sqrt(self.k_rot**2 * np.abs(turn) + self.k_drift**2 * d)
        return sigma_t, sigma_a

    def nominal_cov(self, mean_trans: float, mean_turn: float) -> FloatArray:
        """The covariance of ``(rot1, trans, rot2)`` an estimator is told, for steps of mean
        distance ``mean_trans`` [m] and mean absolute turn ``mean_turn`` [rad]: the random
        part of a mean step plus the largest systematic error on it, ``σ_t² = k_trans² d +
        (ε d)²`` and ``σ_a² = k_rot² a + k_drift² d + (ε a)²`` with ``ε`` the larger of
        ``|ε_r|``, ``|ε_b|`` (or ``systematic_range[1]`` where drawn); the turn variance is
        split evenly between ``rot1`` and ``rot2`` (independent halves that sum to ``σ_a²``).
        Floors of 1 mm and 0.1° keep it positive definite when the model has no noise."""
        eps = max(
            abs(e) if e is not None else self.systematic_range[1]
            for e in (self.wheel_radius_error, self.wheel_base_error)
        )
        d, a = abs(mean_trans), abs(mean_turn)
        var_t = self.k_trans**2 * d + (eps * d) ** 2
        var_a = self.k_rot**2 * a + self.k_drift**2 * d + (eps * a) ** 2
        var_t = max(var_t, 1e-3**2)
        var_half = max(var_a / 2.0, math.radians(0.1) ** 2)
        return np.diag([var_half, var_t, var_half])


@dataclass(frozen=True)
class OdometryGlitch:
    """One injected fault.

    * ``step``: the index ``k`` of the odometry reading it concerns (0 is the first reading;
      the faulty increment is the one from reading ``k - 1`` to ``k``), counted before
      duplicates are inserted;
    * ``time``: the stamp of reading ``k`` in the returned data set (after repair);
    * ``size``: ``heading_jump``: the jump [rad, signed]; ``stall``: the true distance the
      stalled steps did not report [m]; ``duplicate``: 0; ``out_of_order``: how far [s] the
      raw stamp lay before the previous reading's stamp;
    * ``n_steps``: steps affected (a stall's length; 1 otherwise);
    * ``raw_time``: the stamp as the sensor wrote it (differs from ``time`` only for
      ``out_of_order``).
    """

    kind: GlitchKind
    step: int
    time: float
    size: float
    n_steps: int = 1
    raw_time: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind, "step": self.step, "time": self.time, "size": self.size,
            "n_steps": self.n_steps, "raw_time": self.raw_time,
        }  # fmt: skip


@dataclass(frozen=True)
class OdometryGlitches:
    """What :func:`corrupt_odometry` did: the glitches in step order and the systematic
    errors it used (given or drawn)."""

    glitches: tuple[OdometryGlitch, ...]
    wheel_radius_error: float
    wheel_base_error: float

    def __len__(self) -> int:
        return len(self.glitches)

    def __iter__(self) -> Iterator[OdometryGlitch]:
        return iter(self.glitches)

    def of_kind(self, kind: GlitchKind) -> tuple[OdometryGlitch, ...]:
        return tuple(g for g in self.glitches if g.kind == kind)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able, for a data set's metadata and result folders."""
        return {
            "wheel_radius_error": self.wheel_radius_error,
            "wheel_base_error": self.wheel_base_error,
            "glitches": [g.to_dict() for g in self.glitches],
        }


def corrupt_odometry(
    dataset: Dataset, model: OdometryErrorModel, rng: np.random.Generator
) -> tuple[Dataset, OdometryGlitches]:
    """``dataset`` with its odometry rebuilt from the true path under ``model``, and the
    list of what was injected (see the module docstring for the model).

    The readings are placed at the stamps of the data set's :class:`Odometry` events, or, if
    it has none, at the stamps of its laser scans (its :class:`Control` events are then
    dropped); the true pose at each stamp is interpolated from ``dataset.truth`` (exact where
    the stamps match). Every other event is kept. ``rng`` is split into independent streams
    for the systematic errors, the noise and the glitches, so that switching glitches off
    leaves the noise the same draw for draw.
    """
    truth = dataset.truth
    if truth.times is None or truth.poses is None or truth.times.size < 2:
        raise InputError(
            f"corrupt_odometry: data set {dataset.name!r} has no true path to build odometry from"
        )
    stamps = _stamps(dataset)
    if stamps.size < 2:
        raise InputError(
            f"corrupt_odometry: data set {dataset.name!r} has {stamps.size} odometry or scan "
            "stamps; expected at least 2"
        )
    true_poses = interpolate_poses(truth.times, truth.poses, stamps)
    # Signed steps: a step back (or a jitter while turning in place) keeps both rotations
    # small, so scaling them scales the turn, not the unsigned form's rot1 = ±π.
    u = signed_odometry_steps(odometry_control(true_poses[:-1], true_poses[1:]))
    sys_rng, noise_rng, glitch_rng = rng.spawn(3)

    eps_r, eps_b = (
        e if e is not None else _draw_systematic(model.systematic_range, sys_rng)
        for e in (model.wheel_radius_error, model.wheel_base_error)
    )
    # Systematic part: d' = (1 + ε_r) d, a' = s a with s = (1 + ε_r) / (1 + ε_b).
    s = (1.0 + eps_r) / (1.0 + eps_b)
    out = np.column_stack([s * u[:, 0], (1.0 + eps_r) * u[:, 1], s * u[:, 2]])
    # Random part: independent per step, variance linear in distance and turn.
    sigma_t, sigma_a = model.step_sigmas(u[:, 1], wrap_angle(u[:, 0] + u[:, 2]))
    z = noise_rng.standard_normal((u.shape[0], 2))
    out[:, 1] += sigma_t * z[:, 0]
    out[:, 0] += 0.5 * sigma_a * z[:, 1]  # e_turn / 2 before and after the translation
    out[:, 2] += 0.5 * sigma_a * z[:, 1]

    glitches, odo_times, duplicates = _inject_glitches(out, u, stamps, model, glitch_rng)
    odom = integrate_odometry(true_poses[0], out)
    new_events = _merge_events(dataset.events, odom, odo_times, duplicates)
    trans_mean = float(np.mean(np.abs(u[:, 1])))
    turn_mean = float(np.mean(np.abs(wrap_angle(u[:, 0] + u[:, 2]))))
    record = OdometryGlitches(tuple(glitches), float(eps_r), float(eps_b))
    metadata = {
        **dataset.metadata,
        "odometry": "true path + OdometryErrorModel (slamkit.sim.odometry_errors)",
        "odometry_errors": {"model": config_to_dict(model), **record.to_dict()},
    }
    corrupted = replace(
        dataset,
        events=tuple(new_events),
        motion=MotionSpec(
            OdometryModel(), model.nominal_cov(trans_mean, turn_mean), source="odometry"
        ),
        metadata=metadata,
    )
    return corrupted, record


def _stamps(dataset: Dataset) -> FloatArray:
    """Stamps of the Odometry events, else of the laser scans (in stream order)."""
    odo = [ev.t for ev in dataset.events if isinstance(ev, Odometry)]
    if odo:
        return np.asarray(odo, dtype=float)
    scans = [ev.t for ev in dataset.events if isinstance(ev, LaserScan)]
    return np.asarray(scans, dtype=float)


def _draw_systematic(bounds: tuple[float, float], rng: np.random.Generator) -> float:
    """``±U(bounds)`` with a random sign."""
    magnitude = rng.uniform(bounds[0], bounds[1])
    return float(magnitude if rng.random() < 0.5 else -magnitude)


def _inject_glitches(
    out: FloatArray,
    u: FloatArray,
    stamps: FloatArray,
    model: OdometryErrorModel,
    rng: np.random.Generator,
) -> tuple[list[OdometryGlitch], FloatArray, set[int]]:
    """Put glitches into the increments ``out (N-1, 3)`` in place; return the glitches, the
    readings' stamps after repair and the readings to publish twice. Reading ``k`` ends
    increment ``k - 1``. A heading jump inside a stall is dropped (the wheels report nothing
    then), as is a stall starting inside another; at most one stamp glitch per reading."""
    n = stamps.size
    draws = rng.random((4, n))  # one per reading and kind; reading 0 has no increment
    stalled = np.zeros(n, dtype=bool)
    glitches: list[OdometryGlitch] = []
    times = stamps.copy()
    duplicates: set[int] = set()
    for k in range(1, n):
        if not stalled[k] and draws[0, k] < model.stall_rate:
            lo, hi = (int(v) for v in model.stall_steps)
            length = min(int(rng.integers(lo, hi + 1)), n - k)
            stalled[k : k + length] = True
            lost = float(np.sum(np.abs(u[k - 1 : k - 1 + length, 1])))
            out[k - 1 : k - 1 + length] = 0.0
            glitches.append(OdometryGlitch("stall", k, float(stamps[k]), lost, length))
        if not stalled[k] and draws[1, k] < model.heading_jump_rate:
            lo_deg, hi_deg = model.heading_jump_deg
            jump = math.radians(rng.uniform(lo_deg, hi_deg)) * (1.0 if rng.random() < 0.5 else -1.0)
            out[k - 1, 2] += jump
            glitches.append(OdometryGlitch("heading_jump", k, float(stamps[k]), jump))
        if draws[2, k] < model.out_of_order_rate:
            lag = float(rng.uniform(*model.out_of_order_lag))
            repaired = min(float(stamps[k - 1]) + STAMP_REPAIR_STEP, float(stamps[k]))
            times[k] = repaired
            raw = float(stamps[k - 1]) - lag
            glitches.append(OdometryGlitch("out_of_order", k, repaired, lag, 1, raw))
        elif draws[3, k] < model.duplicate_rate:
            duplicates.add(k)
            glitches.append(OdometryGlitch("duplicate", k, float(stamps[k]), 0.0))
    return glitches, times, duplicates


def _merge_events(
    events: tuple[Event, ...], odom: FloatArray, times: FloatArray, duplicates: set[int]
) -> list[Event]:
    """The non-odometry events with the new readings, ordered by stamp; at equal stamps an
    odometry reading comes first (as the readers put it), other events keep their order."""
    kept = [ev for ev in events if not isinstance(ev, Odometry | Control)]
    readings: list[Event] = []
    for k in range(odom.shape[0]):
        readings.append(Odometry(float(times[k]), odom[k].copy()))
        if k in duplicates:
            readings.append(Odometry(float(times[k]), odom[k].copy()))
    # The loader kit's merge: odometry (the motion) before the readings at one stamp, each
    # list's order kept.
    return list(assemble_events(readings, kept))
