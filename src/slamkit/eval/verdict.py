"""A run's verdict in one line: "looks consistent", or "doubtful: …" with the reasons.

A wrong result looks like a right one unless the run says what it saw, and a list of
warnings is easy to skim past. The verdict reads the run's findings
(:class:`~slamkit.eval.records.RunScores.warnings`) by stated rules:

1. **The estimator's own doubts** (:class:`~slamkit.estimation.contract.RunWarning`:
   odometry glitches overridden, track lost, long unmatched stretches, many closures
   refused, a strained final graph, odometry that says nothing, …) each make it doubtful,
   named by their kind;
2. **The consistency monitor** (:class:`~slamkit.eval.monitor.ConsistencyWarning`: a
   window of NEES or NIS beyond its χ² band) makes it doubtful, named by the statistic
   and the direction ("NEES over-confident");
3. otherwise it **looks consistent**: nothing the run can see of itself argues against
   it. That is not a proof of accuracy; with ground truth, the errors say how good it is.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["CONSISTENT", "Verdict", "verdict"]

CONSISTENT = "looks consistent"
"""The verdict of a run without a finding."""


@dataclass(frozen=True)
class Verdict:
    """The reasons to doubt a run (empty: it looks consistent), in the order found."""

    reasons: tuple[str, ...] = ()

    @property
    def consistent(self) -> bool:
        return not self.reasons

    @property
    def line(self) -> str:
        """``"looks consistent"`` or ``"doubtful: reason; reason"``."""
        return CONSISTENT if self.consistent else "doubtful: " + "; ".join(self.reasons)

    def as_dict(self) -> dict[str, Any]:
        return {"consistent": self.consistent, "line": self.line, "reasons": list(self.reasons)}


def _reason(finding: Any) -> str:
    kind = getattr(finding, "kind", None)
    if isinstance(kind, str):  # the estimator's own (rule 1)
        return kind.replace("_", " ")
    statistic = getattr(finding, "statistic", None)
    direction = getattr(finding, "direction", None)
    if isinstance(statistic, str):  # the consistency monitor (rule 2)
        return f"{statistic.upper()} {direction}" if direction else statistic.upper()
    return type(finding).__name__  # any other finding still counts, by its type's name


def verdict(findings: Sequence[Any]) -> Verdict:
    """The verdict of a run with these findings (module docstring), each reason once."""
    reasons: list[str] = []
    for finding in findings:
        reason = _reason(finding)
        if reason not in reasons:
            reasons.append(reason)
    return Verdict(tuple(reasons))
