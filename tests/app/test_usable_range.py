"""`run occupancy-mapping` and `map occupancy` make the same map by default (one usable range)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from slamkit.app import RunRequest, run_job
from slamkit.app.mapping import USABLE_RANGE, occupancy_map_job, with_usable_range
from slamkit.cli.map_cmd import DEFAULT_MAX_RANGE
from slamkit.datasets import load_dataset


def test_with_usable_range_fills_only_an_unset_range() -> None:
    assert with_usable_range({})["model"]["max_range"] == USABLE_RANGE == DEFAULT_MAX_RANGE
    kept = with_usable_range({"model": {"max_range": 5.0, "p_occ": 0.7}, "resolution": 0.1})
    assert kept == {"model": {"max_range": 5.0, "p_occ": 0.7}, "resolution": 0.1}


def test_run_and_map_commands_build_the_same_grid(tmp_path: Path) -> None:
    ds = load_dataset("rooms-laser", seed=0)
    report = run_job(
        RunRequest(
            "occupancy-mapping",
            "rooms-laser",
            tmp_path / "run",
            estimator_config={"resolution": 0.1},
        )
    )
    cfg = json.loads((tmp_path / "run" / "config.json").read_text())
    assert cfg["estimator"]["model"]["max_range"] == USABLE_RANGE
    mapped = occupancy_map_job(
        ds, 0.1, tmp_path / "map", agreement=False, config=with_usable_range({})
    )
    a, b = report.result.output.grid, mapped.grid
    assert a is not None
    # both grids lie on one lattice anchored at the origin: compare the cells they share
    lo = np.maximum(a.origin_xy, b.origin_xy)
    hi = np.minimum(np.array(a.bounds()[2:]), np.array(b.bounds()[2:]))
    ra = np.round((lo - a.origin_xy) / 0.1).astype(int)
    rb = np.round((lo - b.origin_xy) / 0.1).astype(int)
    n = np.round((hi - lo) / 0.1).astype(int)
    pa = a.prob[ra[1] : ra[1] + n[1], ra[0] : ra[0] + n[0]]
    pb = b.prob[rb[1] : rb[1] + n[1], rb[0] : rb[0] + n[0]]
    assert pa.size > 1000
    np.testing.assert_allclose(pa, pb, atol=1e-6)
