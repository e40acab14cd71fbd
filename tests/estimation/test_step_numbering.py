"""One step numbering: every registered estimator, run on a data set engineered to diverge at
a known step, reports that step in its :class:`~slamkit.errors.ConvergenceError` — whether
the runner catches the non-finite estimate or the estimator's own checks do.

The engineered fault: one control of the simulated world is replaced by a finite turn rate
of 1.7e308 rad/s held for 10 s, which passes the data set's validation (every number is
finite) but turns the heading of any pose moved by it into NaN.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from slamkit.datasets import Dataset, load_dataset
from slamkit.datasets.stream import Control, group_by_time
from slamkit.errors import ConvergenceError
from slamkit.pipeline import ESTIMATORS, run

FAULT_AT = 40
"""Index (among the controls) of the control that carries the fault."""

CANNOT_DIVERGE = {
    "least-squares": "a fresh static fix at every reading event: nothing is carried over",
    "ekf-mapping": "maps with the known poses: no motion to blow up",
    "occupancy-mapping": "maps with the known poses: no motion to blow up",
}
"""Estimators a bad control cannot derail, and why (each is checked to finish finite)."""

DATA = {
    "mcl": "rooms-laser",
    "occupancy-mapping": "rooms-laser",
    "laser-odometry": "rooms-laser",
    "graph-slam": "rooms-laser",
    "grid-rbpf": "rooms-laser",
    "range-only-slam": "five-features-range",
}
"""The simulated world each estimator runs on (default: five-features)."""


def _faulty(name: str) -> tuple[Dataset, int]:
    data = load_dataset(name, seed=0)
    events = list(data.events)
    controls = [i for i, e in enumerate(events) if isinstance(e, Control)]
    e = events[controls[FAULT_AT]]
    assert isinstance(e, Control)
    events[controls[FAULT_AT]] = Control(e.t, np.array([e.u[0], 1.7e308]), 10.0)
    bad = dataclasses.replace(data, events=tuple(events))
    # the runner's numbering: one step per distinct time stamp, the first being step 1
    step = next(s for s, (t, _) in enumerate(group_by_time(bad.events), start=1) if t == e.t)
    return bad, step


@pytest.mark.parametrize("estimator", sorted(ESTIMATORS))
def test_every_estimator_reports_the_step_it_diverged_at(estimator: str) -> None:
    data, step = _faulty(DATA.get(estimator, "five-features"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the overflow itself
        if estimator in CANNOT_DIVERGE:
            result = run(estimator, data, seed=0)
            assert np.isfinite(result.poses).all()
            return
        with pytest.raises(ConvergenceError) as info:
            run(estimator, data, seed=0)
    assert info.value.step == step, str(info.value)
    assert f"step {step}" in str(info.value)
