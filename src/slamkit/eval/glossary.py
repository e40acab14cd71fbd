"""What each number of ``metrics.json`` is called, its unit and what it means, in one table.

The console's summary and the report page read their labels, units and one-line
explanations from :data:`METRICS`, so the two say the same thing in the same units:
angles in degrees (``metrics.json`` keeps radians, as the library computes them, except
where a key ends in ``_deg``), shares in per cent, distances in metres, times in seconds.
A key the table does not name still gets a label, a unit and a group from its record
(:data:`RECORDS`) and the rules of :func:`describe`, so nothing a run writes is left
without its unit.

Groups, in the order a page shows them (:data:`GROUPS`):

* **accuracy against the truth** — errors against a true path, map or association (only
  where the data set has one);
* **consistency** — whether the estimator's own uncertainty matches its errors (NEES) or
  its innovations (NIS);
* **what the estimator says of itself** — the quality signals of
  :mod:`slamkit.eval.signals`, there with or without ground truth;
* **the run** — seed, steps, time.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
from typing import Any

__all__ = [
    "GROUPS",
    "METRICS",
    "RECORDS",
    "MetricInfo",
    "MetricRow",
    "describe",
    "flatten_raw",
    "format_number",
    "metric_rows",
]

ACCURACY = "accuracy against the truth"
CONSISTENCY = "consistency"
SELF = "what the estimator says of itself"
RUN = "the run"
GROUPS = (ACCURACY, CONSISTENCY, SELF, RUN)
"""The groups in page order."""

_DEG = 180.0 / math.pi
_SCALE = {"deg": _DEG, "%": 100.0}  # from radians, from a fraction


@dataclass(frozen=True)
class MetricInfo:
    """How one ``metrics.json`` key (dotted: ``ate.rmse``) is shown: its ``label``, its
    ``unit`` (``"m"``, ``"deg"``, ``"s"``, ``"%"`` or ``""``), a one-line ``explanation``,
    its ``group``, the format of its number, and whether the console's summary shows it.
    ``scale`` takes the stored value to the unit shown (radians to degrees, a fraction to
    per cent); ``spread``: the key of a standard deviation shown as ``mean ± std``."""

    key: str
    group: str
    label: str
    unit: str = ""
    explanation: str = ""
    fmt: str = ".3f"
    console: bool = False
    scale: float = 1.0
    spread: str | None = None

    @property
    def heading(self) -> str:
        """``label [unit]``, or the label alone for a plain number."""
        return f"{self.label} [{self.unit}]" if self.unit else self.label


def _m(
    key: str, group: str, label: str, unit: str = "", explanation: str = "", **kw: Any
) -> MetricInfo:
    scale = _SCALE.get(unit, 1.0) if not key.endswith(("_deg", "_pct")) else 1.0
    return MetricInfo(key, group, label, unit, explanation, scale=kw.pop("scale", scale), **kw)


METRICS: tuple[MetricInfo, ...] = (
    # accuracy against the truth
    _m("ate.rmse", ACCURACY, "ATE RMSE, SE(2)-aligned", "m",
       "root mean square distance from the true positions after the rotation and shift that "
       "best overlay the two paths: the shape of the path", console=True),
    _m("ate_unaligned.rmse", ACCURACY, "ATE RMSE, unaligned", "m",
       "the same in the frame the run started in, without overlaying: drift included",
       console=True),
    _m("ate_unaligned.heading_rmse", ACCURACY, "heading RMSE, unaligned", "deg",
       "root mean square of the heading error", fmt=".2f", console=True),
    _m("final_position_error", ACCURACY, "final position error", "m",
       "distance between the estimated and the true position at the last step", console=True),
    _m("rpe_1_step.translation_rmse", ACCURACY, "RPE over one step, translation", "m",
       "error of the motion between consecutive steps: the local drift"),
    _m("rpe_1_step.rotation_rmse", ACCURACY, "RPE over one step, rotation", "deg",
       "error of the turn between consecutive steps", fmt=".2f"),
    _m("rpe_10_m.translation_rmse", ACCURACY, "RPE over 10 m, translation", "m",
       "error of the motion over each 10 m of path"),
    _m("rpe_10_m.rotation_rmse", ACCURACY, "RPE over 10 m, rotation", "deg",
       "error of the turn over each 10 m of path", fmt=".2f"),
    _m("convergence.time_s", ACCURACY, "converged after", "s",
       "time until the position error stayed below the threshold for the hold time (a start "
       "without a prior)", fmt=".1f", console=True),
    _m("convergence.position_error_after.median", ACCURACY,
       "median position error after converging", "m", "half the steps after it are closer",
       console=True),
    _m("convergence.lost_fraction", ACCURACY, "time lost after converging", "%",
       "share of the time after converging with the position error above the lost threshold",
       fmt=".1f"),
    _m("landmarks.rmse", ACCURACY, "landmark RMSE", "m",
       "root mean square distance from each mapped landmark to its true one, maps overlaid",
       console=True),
    _m("landmarks.n_matched", ACCURACY, "landmarks matched to a true one", "",
       "mapped landmarks paired with a true landmark", fmt="d", console=True),
    _m("landmarks.n_missing", ACCURACY, "true landmarks not mapped", "",
       "true landmarks no mapped landmark was paired with", fmt="d", console=True),
    _m("landmarks.n_spurious", ACCURACY, "mapped landmarks near no true one", "",
       "landmarks of the final map left unpaired by the position matching", fmt="d"),
    _m("association.accuracy", ACCURACY, "association accuracy", "%",
       "share of readings the estimator gave to the right landmark", fmt=".2f", console=True),
    _m("association.duplicates", ACCURACY, "spurious landmarks (match no true one)", "",
       "landmarks of the final map that are no true landmark's estimate (mapped twice, "
       "clutter); deleted features are not counted", fmt="d", console=True),
    _m("association.not_in_map", ACCURACY, "features with readings not in the map", "",
       "features deleted or still provisional at the end; not counted as spurious", fmt="d"),
    _m("association.spurious_created", ACCURACY, "spurious feature creations", "",
       "features started that are no true landmark's estimate, deleted ones included (a "
       "landmark started again after its feature was deleted counts each time)", fmt="d"),
    _m("association.merged", ACCURACY, "merged landmarks (one for several true)", "",
       "landmarks of the final map that stand for more than one true landmark", fmt="d",
       console=True),
    _m("gps.rmse", ACCURACY, "GPS RMSE, SE(2)-aligned", "m",
       "root mean square distance from the GPS fixes kept, paths overlaid", console=True),
    _m("relations.translation_mean", ACCURACY, "relation error, translation", "m",
       "mean ± std of the error of the reference relations' translations",
       spread="relations.translation_std", console=True),
    _m("relations.rotation_mean_deg", ACCURACY, "relation error, rotation", "deg",
       "mean ± std of the error of the reference relations' rotations", fmt=".1f",
       spread="relations.rotation_std_deg", console=True),
    _m("relations.covered_fraction", ACCURACY, "relations covered", "%",
       "share of the reference relations inside the run", fmt=".0f", console=True),
    # consistency
    _m("nees.mean", CONSISTENCY, "mean NEES (3 dof)", "",
       "error squared in units of the estimator's own covariance: 3 when it is honest, "
       "above: over-confident", fmt=".2f", console=True),
    _m("nees.fraction_in_band", CONSISTENCY, "steps with NEES in its 95 % band", "%",
       "95 % of steps for an honest covariance", fmt=".1f"),
    _m("nis.mean_nis_per_dof", CONSISTENCY, "mean NIS per degree of freedom", "",
       "innovation squared in units of its predicted covariance: 1 when honest", fmt=".2f"),
    _m("nis.fraction_updates_in_band", CONSISTENCY, "updates with NIS in its 95 % band", "%",
       "95 % of updates for an honest filter", fmt=".1f"),
    _m("nis.fraction_windows_consistent", CONSISTENCY, "NIS windows consistent", "%",
       "share of the windows of 50 updates whose NIS sum lies in its χ² band", fmt=".1f"),
    # what the estimator says of itself
    _m("signals.keyframes", SELF, "keyframes", "",
       "scans kept as the map's reference poses", fmt="d", console=True),
    _m("signals.matched_share", SELF, "scans matched", "%",
       "share of the scans the matcher aligned; the rest went on odometry alone", fmt=".1f",
       console=True),
    _m("signals.closures_kept", SELF, "loop closures kept", "",
       "edges between revisited places in the final graph", fmt="d", console=True),
    _m("signals.closures_refused", SELF, "loop closures refused", "",
       "candidates refused by a check (score, degeneracy, consistency)", fmt="d",
       console=True),
    _m("signals.graph_chi2_per_dof", SELF, "final graph χ² per degree of freedom", "",
       "the graph's cost over 3 × closures kept: near 1 when closures and path agree, far "
       "above: they contradict each other", fmt=".2f", console=True),
    _m("signals.neff_share_mean", SELF, "effective particles, mean", "%",
       "N_eff = 1/Σw² as a share of the particles, mean over the updates; near 0: one "
       "particle carries the weight", fmt=".1f", console=True),
    _m("signals.neff_share_min", SELF, "effective particles, least", "%",
       "the same at the worst update", fmt=".1f", console=True),
    _m("signals.nis_per_dof", SELF, "mean NIS per degree of freedom", "",
       "innovations against the filter's own prediction of them: 1 when honest", fmt=".2f",
       console=True),
    _m("signals.nis_in_band", SELF, "updates with NIS in its 95 % band", "%",
       "95 % for an honest filter", fmt=".1f", console=True),
    _m("signals.landmarks_created", SELF, "landmarks created", "",
       "features started from readings; = kept + provisional + deleted", fmt="d",
       console=True),
    _m("signals.landmarks_kept", SELF, "landmarks in the map", "",
       "confirmed landmarks in the final map", fmt="d", console=True),
    _m("signals.landmarks_provisional", SELF, "landmarks still provisional", "",
       "features not yet confirmed at the end: not in the map", fmt="d", console=True),
    _m("signals.landmarks_deleted", SELF, "landmarks deleted", "",
       "features removed after missing where they should have been seen", fmt="d",
       console=True),
    # the run
    _m("seed", RUN, "seed", "", "seed of the simulator and the estimator", fmt="d"),
    _m("steps", RUN, "steps", "", "poses the estimator reported", fmt="d"),
    _m("matched_steps", RUN, "steps matched to the truth", "",
       "steps with a true pose within half a step's time", fmt="d"),
    _m("runtime.total_seconds", RUN, "run time", "s",
       "the estimator's wall-clock time over all steps", console=True),
    _m("runtime.mean_step_seconds", RUN, "mean step time", "s", "", fmt=".6f"),
    _m("runtime.max_step_seconds", RUN, "largest step time", "s", "", fmt=".6f"),
)  # fmt: skip
"""The table of named metrics, in the order shown."""

RECORDS: dict[str, tuple[str, str]] = {
    "ate": (ACCURACY, "ATE, SE(2)-aligned"),
    "ate_unaligned": (ACCURACY, "ATE, unaligned"),
    "rpe_1_step": (ACCURACY, "RPE over one step"),
    "rpe_10_m": (ACCURACY, "RPE over 10 m"),
    "convergence": (ACCURACY, "convergence"),
    "landmarks": (ACCURACY, "landmark error"),
    "landmarks_matched_by": (ACCURACY, "landmarks matched by"),
    "association": (ACCURACY, "association"),
    "gps": (ACCURACY, "GPS error"),
    "relations": (ACCURACY, "relation error"),
    "nees": (CONSISTENCY, "NEES"),
    "nis": (CONSISTENCY, "NIS"),
    "signals": (SELF, "signals"),
    "runtime": (RUN, "run time"),
}
"""Group and name of each record of ``metrics.json``, for the keys :data:`METRICS` does
not name."""

_BY_KEY = {m.key: m for m in METRICS}
_METRE_RECORDS = ("ate", "ate_unaligned", "rpe_1_step", "rpe_10_m", "gps", "landmarks")


def _unit_by_rule(key: str) -> str:
    """The unit of an unnamed key from its name and record."""
    head, _, last = key.rpartition(".")
    root = key.split(".", 1)[0]
    if last.endswith("_deg"):
        return "deg"
    if any(w in last for w in ("rotation", "heading", "angle")):
        return "deg"
    if "heading_error" in head:
        return "deg"
    if last.endswith(("_s", "seconds")) or last == "duration_s":
        return "s"
    if last.startswith(("fraction", "share")) or last.endswith(("_fraction", "_share")):
        return "%"
    if last.endswith("_m") or "position_error" in head:
        return "m"
    if last in ("count", "fixes", "used", "steps", "total", "windows", "dof", "delta") or (
        last.endswith("scale")
    ):
        return ""
    if last.startswith(("n_", "rejected", "unchecked", "outside", "window")):
        return ""
    if root in _METRE_RECORDS or last.startswith("translation") or last == "max_gap":
        return "m"
    return ""


def describe(key: str) -> MetricInfo:
    """How the ``metrics.json`` key ``key`` (dotted) is shown: its entry in :data:`METRICS`,
    or one made from its record (:data:`RECORDS`) and its name — radians shown in degrees,
    fractions in per cent, the errors of a path or map in metres."""
    if key in _BY_KEY:
        return _BY_KEY[key]
    root, _, rest = key.partition(".")
    group, name = RECORDS.get(root, (RUN, root.replace("_", " ")))
    words = rest.replace(".", " › ").replace("_", " ")
    label = f"{name}, {words}" if words else name
    unit = _unit_by_rule(key) if rest else ""
    scale = 1.0 if key.endswith("_deg") else _SCALE.get(unit, 1.0)
    return MetricInfo(key, group, label, unit, "", fmt="", scale=scale)


def flatten_raw(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested records as ``{dotted key: value}`` in order; a record that is only
    ``{"skipped": reason}`` stays one entry holding it."""
    out: dict[str, Any] = {}
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and set(value) != {"skipped"}:
            out.update(flatten_raw(value, f"{name}."))
        else:
            out[name] = value
    return out


def format_number(value: Any, fmt: str = "") -> str:
    """A value as shown: ``fmt`` for a number when given, else 4 significant digits (an
    exponent for the very large and small), ``true``/``false``, lists of up to four numbers
    inline, longer ones as their length."""
    if isinstance(value, bool) or value is None:
        return str(value).lower()
    if isinstance(value, (int, float)):
        if fmt == "d":
            return f"{round(value):d}"
        if fmt:
            return format(value, fmt)
        if isinstance(value, int):
            return str(value)
        if not math.isfinite(value):
            return str(value)
        if value != 0 and (abs(value) >= 1e6 or abs(value) < 1e-3):
            return f"{value:.3e}"
        return f"{value:.4g}" if abs(value) < 1000 else f"{value:.1f}"
    if isinstance(value, str):
        return value
    if isinstance(value, (list, tuple)):
        if len(value) <= 4 and all(isinstance(v, (int, float)) for v in value):
            return ", ".join(format_number(v) for v in value)
        return f"[{len(value)} values]"
    return str(value)


@dataclass(frozen=True)
class MetricRow:
    """One number as shown: its description, the value in the unit shown, the text."""

    info: MetricInfo
    value: Any
    text: str
    named: bool
    """Whether :data:`METRICS` names it (False: a detail of its record)."""


def _shown(info: MetricInfo, value: Any, flat: Mapping[str, Any]) -> tuple[Any, str]:
    if isinstance(value, Mapping) and "skipped" in value:
        return value, f"skipped: {value['skipped']}"
    if isinstance(value, (list, tuple)) and info.scale != 1.0:
        value = [v * info.scale if isinstance(v, (int, float)) else v for v in value]
        return value, format_number(value, info.fmt)
    if isinstance(value, (int, float)) and not isinstance(value, bool) and info.scale != 1.0:
        value = value * info.scale
    text = format_number(value, info.fmt)
    if info.spread is not None and isinstance(flat.get(info.spread), (int, float)):
        text += " ± " + format_number(flat[info.spread] * info.scale, info.fmt)
    return value, text


SKIP = ("estimator", "dataset", "diagnostics", "reading", "warnings", "verdict")
"""Top-level keys of ``metrics.json`` that are not numbers to tabulate (shown elsewhere)."""


def metric_rows(metrics: Mapping[str, Any]) -> Iterator[MetricRow]:
    """The numbers of a run's ``metrics.json`` (or :meth:`RunScores.as_dict`) as rows: the
    named ones in the order of :data:`METRICS`, then every other key in the file's order,
    each in its unit (radians as degrees, fractions as per cent). A record that does not
    apply (``{"skipped": reason}``) is one row. :data:`SKIP` are left out."""
    flat = flatten_raw({k: v for k, v in metrics.items() if k not in SKIP})
    spreads = {m.spread for m in METRICS if m.spread}
    for info in METRICS:
        if info.key in flat:
            yield MetricRow(info, *_shown(info, flat[info.key], flat), named=True)
    for key, value in flat.items():
        if key in _BY_KEY or key in spreads:
            continue
        info = describe(key)  # a record that does not apply is shown among the named
        if isinstance(value, (str, bool)) or value is None:  # words have no unit
            info = replace(info, unit="", scale=1.0)
        yield MetricRow(info, *_shown(info, value, flat), named=isinstance(value, Mapping))
