"""What a run knows of itself without ground truth: the quality signals of its estimator.

On a user's own log there is no true path to score a run against, and a wrong result looks
like a right one. What the estimator counted of itself (its ``diagnostics``) still says a
good deal, once it is read the same way for every estimator:

* **keyframes** and the **share of scans matched** (``matched / scans``; laser trackers);
* **loop closures** kept and refused (graph SLAM) and the final graph's **normalised χ²**:
  its cost ``Σ eᵀ Ω e`` over its degrees of freedom. The first keyframe is fixed and every
  other keyframe has one edge to its predecessor, so the graph has ``3 (E − K + 1)`` more
  residuals than unknowns: three per loop closure kept. With consistent information
  matrices the ratio is near 1; far above it, the closures and the path disagree. A graph
  without a closure has no redundancy and no χ² to speak of;
* **particles' effective sample size** ``N_eff = 1 / Σ wᵢ²`` as a share of the particles,
  its mean and its least over the updates (particle filters): near 0, one particle carries
  the whole weight;
* **NIS** per degree of freedom (filters; 1 when the filter's innovations are as large as
  it predicts) and the share of updates inside their 95 % χ² band (:mod:`.innovations`);
* **landmarks** created, kept (the map), still provisional and deleted (landmark SLAM),
  which add up: ``created = kept + provisional + deleted`` where the estimator reports all
  four (EKF-SLAM).

None of this proves a result right; it is what argues for or against it when nothing else
can. :func:`self_signals` reads them from a run's diagnostics and NIS summary.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

from slamkit.eval.innovations import NisSummary

__all__ = ["SelfSignals", "self_signals"]


@dataclass(frozen=True)
class SelfSignals:
    """The quality signals of a run (module docstring); ``None``: the estimator does not
    have that signal. ``as_dict`` leaves those out."""

    keyframes: int | None = None
    scans: int | None = None
    scans_matched: int | None = None
    matched_share: float | None = None
    """``scans_matched / scans``."""
    closures_kept: int | None = None
    closures_refused: int | None = None
    """Loop closures tried and refused, for any reason."""
    graph_dof: int | None = None
    """``3 × closures_kept``: the final graph's residuals beyond its unknowns."""
    graph_chi2_per_dof: float | None = None
    """The final graph's cost over ``graph_dof`` (None: no closure, nothing to judge)."""
    particles: int | None = None
    neff_share_mean: float | None = None
    """Mean ``N_eff / particles`` over the measurement updates."""
    neff_share_min: float | None = None
    nis_per_dof: float | None = None
    nis_in_band: float | None = None
    """Share of updates whose NIS lies inside its two-sided 95 % χ² band."""
    landmarks_created: int | None = None
    landmarks_kept: int | None = None
    """Landmarks in the final map (confirmed; the best particle's in FastSLAM)."""
    landmarks_provisional: int | None = None
    """Features still provisional at the end: in the state, not in the map."""
    landmarks_deleted: int | None = None

    @property
    def empty(self) -> bool:
        return all(getattr(self, f.name) is None for f in fields(self))

    def as_dict(self) -> dict[str, Any]:
        return {f.name: v for f in fields(self) if (v := getattr(self, f.name)) is not None}


def _int(d: Mapping[str, Any], key: str) -> int | None:
    value = d.get(key)
    return int(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def _float(d: Mapping[str, Any], key: str) -> float | None:
    value = d.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value)


def _share(part: float | None, whole: float | None) -> float | None:
    return None if part is None or not whole else part / whole


def self_signals(diagnostics: Mapping[str, Any], nis: NisSummary | None = None) -> SelfSignals:
    """The quality signals in an estimator's ``diagnostics`` (the keys its ``finish``
    writes) and the run's NIS summary, when it has one."""
    d = diagnostics
    out: dict[str, Any] = {"keyframes": _int(d, "keyframes")}
    scans, matched = _int(d, "scans"), _int(d, "matched")
    if scans is not None and matched is not None:
        out.update(scans=scans, scans_matched=matched, matched_share=_share(matched, scans))
    kept = _int(d, "loops_kept")
    if kept is not None:  # graph SLAM
        rejected = d.get("loops_rejected")
        refused = sum(int(v) for v in rejected.values()) if isinstance(rejected, Mapping) else 0
        cost = _float(d, "final_cost")
        out.update(closures_kept=kept, closures_refused=refused, graph_dof=3 * kept)
        out["graph_chi2_per_dof"] = cost / (3 * kept) if cost is not None and kept else None
    particles = next(
        (n for k in ("particles", "n_particles", "particles_mean") if (n := _float(d, k))), None
    )
    if particles:  # grid-rbpf: neff_*; FastSLAM: ess_*; MCL: its shares directly
        out["particles"] = round(particles)
        for stat in ("mean", "min"):
            share = _float(d, f"ess_share_{stat}")
            if share is None:
                count = _float(d, f"neff_{stat}")
                share = _share(count if count is not None else _float(d, f"ess_{stat}"), particles)
            out[f"neff_share_{stat}"] = share
    if nis is not None:
        out.update(nis_per_dof=nis.mean_per_dof, nis_in_band=nis.fraction_in_band)
    else:
        out["nis_per_dof"] = _float(d, "mean_nis_per_dof")
    created = _int(d, "new_features")
    if created is None:
        created = _int(d, "new_landmarks")
    kept_map = _int(d, "n_landmarks")
    if kept_map is None and "n_particles" in d:
        kept_map = _int(d, "landmarks")
    out.update(
        landmarks_created=created,
        landmarks_kept=kept_map,
        landmarks_provisional=_int(d, "n_provisional"),
    )
    removed = [_int(d, k) for k in ("removed_provisional", "removed_confirmed")]
    if all(r is not None for r in removed):
        out["landmarks_deleted"] = sum(r for r in removed if r is not None)
    return SelfSignals(**out)
