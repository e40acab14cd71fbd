"""Summaries of a sweep's results table: NEES and NIS over Monte Carlo seeds with their χ²
bands, the best settings per data set, the failures. Numbers only; the plots are drawn by
:mod:`slamkit.viz.sweep`, imported by :func:`write_report` when it is asked for them.

A *configuration* is one estimator on one data set at one value of every swept setting; its
runs differ only by seed.

* NEES: each run's time-averaged pose NEES (``nees.mean``, 3 dof) is treated as one
  χ²(3) value, and the average over R seeds is held to ``chi2_bounds(3, R)`` — the band
  ``tests/localization`` uses for its 50-seed check. It is conservative: a run's time
  average of correlated steps spreads less than one χ²(3) draw.
* NIS: innovations of a consistent filter are white, so the update-weighted mean NIS per
  degree of freedom over all seeds is compared with ``chi2_bounds(1, U)`` for the U updates
  (counting one degree of freedom per update; readings with more make the true band
  narrower).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from slamkit.errors import InputError
from slamkit.eval import chi2_bounds
from slamkit.sweep.table import read_table

__all__ = [
    "DEFAULT_METRICS",
    "BestSetting",
    "ConsistencyOverSeeds",
    "SweepReport",
    "best_settings",
    "consistency_over_seeds",
    "summarize",
    "write_report",
]

DEFAULT_METRICS = (
    "gps.rmse",
    "relations.translation_mean",
    "ate.rmse",
    "landmarks.rmse",
    "final_position_error",
)
"""The metric :func:`best_settings` ranks by when none is given: the first the table has."""


def _config(row: Mapping[str, Any], swept: Sequence[str]) -> tuple[Any, ...]:
    return (row["estimator"], row["dataset"], *(row.get(s) for s in swept))


def _groups(
    rows: Sequence[Mapping[str, Any]], swept: Sequence[str]
) -> dict[tuple[Any, ...], list[Mapping[str, Any]]]:
    out: dict[tuple[Any, ...], list[Mapping[str, Any]]] = {}
    for r in rows:
        out.setdefault(_config(r, swept), []).append(r)
    return out


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


@dataclass(frozen=True)
class ConsistencyOverSeeds:
    """NEES and NIS of one configuration over its seeds."""

    estimator: str
    dataset: str
    settings: dict[str, Any]
    runs: int
    nees_mean: float | None
    """Average over seeds of each run's mean pose NEES."""
    nees_std: float | None
    """Spread (standard deviation) of the per-run means."""
    nees_band: tuple[float, float] | None
    """``chi2_bounds(dof, runs)``."""
    nees_fraction_in_band: float | None
    """Average over seeds of the fraction of steps inside the one-step 95 % band."""
    nis_per_dof: float | None
    nis_band: tuple[float, float] | None
    nis_updates: int | None

    @property
    def nees_inside(self) -> bool | None:
        if self.nees_mean is None or self.nees_band is None:
            return None
        return self.nees_band[0] <= self.nees_mean <= self.nees_band[1]

    @property
    def nis_inside(self) -> bool | None:
        if self.nis_per_dof is None or self.nis_band is None:
            return None
        return self.nis_band[0] <= self.nis_per_dof <= self.nis_band[1]


def consistency_over_seeds(
    rows: Sequence[Mapping[str, Any]], swept: Sequence[str] = (), probability: float = 0.95
) -> list[ConsistencyOverSeeds]:
    """One :class:`ConsistencyOverSeeds` per configuration with NEES or NIS values (the
    successful runs only)."""
    out = []
    for cfg, group in _groups([r for r in rows if r.get("status") == "ok"], swept).items():
        nees = [v for r in group if (v := _number(r.get("nees.mean"))) is not None]
        dofs = {int(d) for r in group if (d := _number(r.get("nees.dof"))) is not None}
        inband = [v for r in group if (v := _number(r.get("nees.fraction_in_band"))) is not None]
        nis = [
            (v, int(c))
            for r in group
            if (v := _number(r.get("nis.mean_nis_per_dof"))) is not None
            and (c := _number(r.get("nis.count"))) is not None
            and c > 0
        ]
        if not nees and not nis:
            continue
        dof = dofs.pop() if len(dofs) == 1 else 3
        updates = sum(c for _, c in nis)
        out.append(
            ConsistencyOverSeeds(
                estimator=cfg[0],
                dataset=cfg[1],
                settings=dict(zip(swept, cfg[2:], strict=True)),
                runs=len(group),
                nees_mean=float(np.mean(nees)) if nees else None,
                nees_std=float(np.std(nees, ddof=1)) if len(nees) > 1 else None,
                nees_band=chi2_bounds(dof, len(nees), probability) if nees else None,
                nees_fraction_in_band=float(np.mean(inband)) if inband else None,
                nis_per_dof=sum(v * c for v, c in nis) / updates if nis else None,
                nis_band=chi2_bounds(1, updates, probability) if nis else None,
                nis_updates=updates if nis else None,
            )
        )
    return out


@dataclass(frozen=True)
class BestSetting:
    """The configuration of ``estimator`` on ``dataset`` with the lowest mean ``metric``
    over its seeds (among configurations whose every run succeeded, if any did)."""

    estimator: str
    dataset: str
    metric: str
    settings: dict[str, Any]
    mean: float
    values: tuple[float, ...]
    """The metric of each seed, in seed order."""
    runs_ok: int
    runs: int
    candidates: int
    """How many configurations were compared."""


def pick_metric(rows: Sequence[Mapping[str, Any]], metric: str | None = None) -> str:
    """``metric`` if the table has it, else the first of :data:`DEFAULT_METRICS` it has."""
    columns = {c for r in rows for c, v in r.items() if _number(v) is not None}
    if metric is not None:
        if metric not in columns:
            numeric = ", ".join(sorted(c for c in columns if not c.startswith("diagnostics.")))
            raise InputError(f"metric {metric!r}: not a numeric column; the table has {numeric}")
        return metric
    for m in DEFAULT_METRICS:
        if m in columns:
            return m
    raise InputError(f"no metric to rank by: the table has none of {', '.join(DEFAULT_METRICS)}")


def best_settings(
    rows: Sequence[Mapping[str, Any]], swept: Sequence[str], metric: str | None = None
) -> list[BestSetting]:
    """Per estimator and data set, the swept settings with the lowest mean ``metric``."""
    ok_rows = [r for r in rows if r.get("status") == "ok"]
    if not ok_rows:
        return []
    chosen = pick_metric(ok_rows, metric)
    by_pair: dict[tuple[str, str], list[tuple[tuple[Any, ...], list[Mapping[str, Any]]]]] = {}
    for cfg, group in _groups(rows, swept).items():
        by_pair.setdefault((cfg[0], cfg[1]), []).append((cfg, group))
    out = []
    for (est, ds), configs in by_pair.items():
        scored = []
        for cfg, group in configs:
            runs = sorted(group, key=lambda r: r["seed"])
            values = [
                v
                for r in runs
                if r.get("status") == "ok" and (v := _number(r.get(chosen))) is not None
            ]
            if values:
                complete = len(values) == len(runs)
                scored.append((not complete, float(np.mean(values)), cfg, values, len(runs)))
        if not scored:
            continue
        _, mean, cfg, values, n = min(scored, key=lambda s: (s[0], s[1]))
        out.append(
            BestSetting(
                est,
                ds,
                chosen,
                dict(zip(swept, cfg[2:], strict=True)),
                mean,
                tuple(values),
                len(values),
                n,
                len(scored),
            )
        )
    return out


@dataclass(frozen=True)
class SweepReport:
    """Everything :func:`write_report` writes, as numbers."""

    runs: int
    ok: int
    failed: int
    swept: tuple[str, ...]
    consistency: list[ConsistencyOverSeeds] = field(default_factory=list)
    best: list[BestSetting] = field(default_factory=list)
    failures: list[dict[str, Any]] = field(default_factory=list)
    """``key``, ``estimator``, ``dataset``, ``seed``, swept settings and ``error``."""
    files: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        consistency = []
        for c in self.consistency:
            d = asdict(c)
            d.update(nees_inside=c.nees_inside, nis_inside=c.nis_inside)
            consistency.append(d)
        return {
            "runs": self.runs,
            "ok": self.ok,
            "failed": self.failed,
            "swept": list(self.swept),
            "consistency": consistency,
            "best": [asdict(b) for b in self.best],
            "failures": self.failures,
        }


def summarize(
    rows: Sequence[Mapping[str, Any]], swept: Sequence[str], metric: str | None = None
) -> SweepReport:
    """The numbers of a report from a table's rows."""
    failures = [
        {k: r.get(k) for k in ("key", "estimator", "dataset", "seed", *swept, "error")}
        for r in rows
        if r.get("status") != "ok"
    ]
    return SweepReport(
        runs=len(rows),
        ok=len(rows) - len(failures),
        failed=len(failures),
        swept=tuple(swept),
        consistency=consistency_over_seeds(rows, swept),
        best=best_settings(rows, swept, metric),
        failures=failures,
    )


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _settings_text(settings: Mapping[str, Any]) -> str:
    return ", ".join(f"{k.split('.', 1)[-1]}={_fmt(v)}" for k, v in settings.items()) or "—"


def report_markdown(report: SweepReport, name: str = "sweep") -> str:
    """The report as a markdown page."""
    lines = [
        f"# Sweep report: {name}",
        "",
        f"{report.runs} runs: {report.ok} ok, {report.failed} failed.",
        "",
    ]
    if report.consistency:
        lines += [
            "## NEES and NIS over seeds (95 % χ² bands)",
            "",
            "| estimator | data set | settings | seeds | mean NEES ± sd | band | inside | "
            "steps in 1-step band | NIS/dof | band | inside |",
            "|---|---|---|---:|---:|---|---|---:|---:|---|---|",
        ]
        for c in report.consistency:
            nees = "—" if c.nees_mean is None else f"{c.nees_mean:.3f}"
            if c.nees_std is not None:
                nees += f" ± {c.nees_std:.3f}"
            band = "—" if c.nees_band is None else f"{c.nees_band[0]:.3f}–{c.nees_band[1]:.3f}"
            frac = "—" if c.nees_fraction_in_band is None else f"{c.nees_fraction_in_band:.3f}"
            nis = "—" if c.nis_per_dof is None else f"{c.nis_per_dof:.3f}"
            nband = "—" if c.nis_band is None else f"{c.nis_band[0]:.3f}–{c.nis_band[1]:.3f}"
            lines.append(
                f"| {c.estimator} | {c.dataset} | {_settings_text(c.settings)} | {c.runs} | "
                f"{nees} | {band} | {_fmt(c.nees_inside)} | {frac} | {nis} | {nband} | "
                f"{_fmt(c.nis_inside)} |"
            )
        lines.append("")
    if report.best:
        lines += [
            "## Best settings per data set",
            "",
            "| estimator | data set | metric | best settings | mean | per seed | ok / runs | "
            "compared |",
            "|---|---|---|---|---:|---|---:|---:|",
        ]
        for b in report.best:
            per_seed = (
                ", ".join(f"{v:.3g}" for v in b.values)
                if len(b.values) <= 8
                else f"{min(b.values):.3g} … {max(b.values):.3g}"
            )
            lines.append(
                f"| {b.estimator} | {b.dataset} | {b.metric} | {_settings_text(b.settings)} | "
                f"{b.mean:.4g} | {per_seed} | {b.runs_ok} / {b.runs} | {b.candidates} |"
            )
        lines.append("")
    if report.failures:
        lines += [
            "## Failures",
            "",
            "| key | estimator | data set | seed | error |",
            "|---|---|---|---:|---|",
        ]
        for f in report.failures:
            error = str(f.get("error")).replace("|", "\\|")
            lines.append(
                f"| {f['key']} | {f['estimator']} | {f['dataset']} | {f['seed']} | {error} |"
            )
        lines.append("")
    return "\n".join(lines)


def write_report(
    out_dir: str | Path, *, metric: str | None = None, plots: bool = True
) -> SweepReport:
    """Read ``out_dir``'s table and write ``out_dir/report/``: ``report.md``,
    ``report.json`` and (``plots``) one PNG of the ranking metric against each swept
    setting (:func:`slamkit.viz.sweep.metric_against_setting`)."""
    root = Path(out_dir)
    rows = read_table(root)
    meta_file = root / "sweep.json"
    meta = json.loads(meta_file.read_text(encoding="utf-8")) if meta_file.is_file() else {}
    swept = [s for s in meta.get("swept", []) if any(s in r for r in rows)]
    report = summarize(rows, swept, metric)
    folder = root / "report"
    folder.mkdir(exist_ok=True)
    files = ["report.md", "report.json"]
    (folder / "report.md").write_text(
        report_markdown(report, meta.get("name", root.name)), encoding="utf-8"
    )
    (folder / "report.json").write_text(
        json.dumps(report.as_dict(), indent=2, default=str) + "\n", encoding="utf-8"
    )
    ok_rows = [r for r in rows if r.get("status") == "ok"]
    if plots and swept and ok_rows:
        from slamkit.viz import save_figure
        from slamkit.viz.sweep import metric_against_setting_figure

        chosen = pick_metric(ok_rows, metric)
        for setting in swept:
            fig = metric_against_setting_figure(ok_rows, setting, chosen)
            name = f"{chosen}_vs_{setting}.png".replace("/", "_")
            save_figure(fig, folder / name)
            files.append(name)
    return SweepReport(
        report.runs,
        report.ok,
        report.failed,
        report.swept,
        report.consistency,
        report.best,
        report.failures,
        tuple(files),
    )
