"""What a run knows of itself (slamkit.eval.signals) and landmark counts that add up."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets import load_dataset
from slamkit.eval import association_scores, self_signals
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate


def test_graph_slam_signals_from_its_diagnostics() -> None:
    diagnostics = {
        "scans": 641,
        "keyframes": 219,
        "matched": 640,
        "loops_kept": 19,
        "loops_rejected": {"degenerate": 7, "refine:no_convergence": 1},
        "final_cost": 37.13,
    }
    s = self_signals(diagnostics)
    assert s.keyframes == 219 and s.scans_matched == 640
    assert s.matched_share == pytest.approx(640 / 641)
    assert s.closures_kept == 19 and s.closures_refused == 8 and s.graph_dof == 57
    assert s.graph_chi2_per_dof == pytest.approx(37.13 / 57)
    # no closure: no redundancy, no χ² to judge
    assert self_signals({**diagnostics, "loops_kept": 0}).graph_chi2_per_dof is None
    assert self_signals({}).empty and self_signals({}).as_dict() == {}


def test_particle_shares_of_each_filter_kind() -> None:
    rbpf = self_signals({"particles": 30, "neff_mean": 15.0, "neff_min": 3.0})
    assert (rbpf.particles, rbpf.neff_share_mean, rbpf.neff_share_min) == (30, 0.5, 0.1)
    fast = self_signals({"n_particles": 100, "ess_mean": 24.0, "ess_min": 2.0, "landmarks": 9})
    assert fast.neff_share_mean == 0.24 and fast.neff_share_min == 0.02
    assert fast.landmarks_kept == 9


def test_a_simulated_graph_slam_run_reports_its_matches_closures_and_fit() -> None:
    """corridor-loop-laser, seed 0 (the demo): 640 of 641 scans matched, 219 keyframes, 19
    closures kept and 8 refused, final χ² per degree of freedom 0.65."""
    ds = load_dataset("corridor-loop-laser", seed=0)
    result = run("graph-slam", ds)
    d = result.output.diagnostics
    s = evaluate(result, ds).scores.signals
    assert s is not None
    assert s.matched_share == d["matched"] / d["scans"]
    assert s.keyframes == d["keyframes"] and s.closures_kept == d["loops_kept"] > 5
    assert s.graph_chi2_per_dof == pytest.approx(d["final_cost"] / (3 * d["loops_kept"]))
    graph = result.output.graph  # the degrees of freedom: residuals beyond the unknowns
    assert graph is not None and graph.poses.shape[0] == s.keyframes
    assert 3 * graph.n_edges - 3 * (graph.poses.shape[0] - 1) == s.graph_dof
    assert 0.2 < s.graph_chi2_per_dof < 2.0  # measured 0.65: closures and path agree


def test_landmark_counts_add_up_and_deleted_features_are_not_spurious() -> None:
    """EKF-SLAM on landmark-clutter (seed 0) deleting a confirmed landmark at its first miss:
    140 created = 137 in the map + 1 provisional + 2 deleted. The deleted ones got readings;
    counted as spurious they made 1 (Victoria Park: 675 beside a map of 331); among the
    map's landmarks there is none."""
    ds = load_dataset("landmark-clutter", seed=0)
    result = run("ekf-slam", ds, config={"max_misses_confirmed": 1})
    scores = evaluate(result, ds).scores
    s = scores.signals
    assert s is not None and s.landmarks_deleted is not None and s.landmarks_deleted > 0
    assert s.landmarks_created == s.landmarks_kept + s.landmarks_provisional + s.landmarks_deleted
    assert result.output.landmarks is not None
    kept_ids = result.output.landmarks.landmarks.ids
    assert s.landmarks_kept == kept_ids.size
    a = scores.association
    assert a is not None and not hasattr(a, "reason")
    assert a.in_map == s.landmarks_kept and a.duplicates <= a.in_map
    assert a.estimated_landmarks == a.in_map + a.not_in_map == s.landmarks_created
    assert a.not_in_map == s.landmarks_provisional + s.landmarks_deleted
    assert a.duplicates == 0
    chosen, true = result.output.reading_landmarks, np.concatenate(ds.truth.reading_ids)
    assert association_scores(chosen, true).duplicates == 1  # the old count, deleted included


def test_association_counts_over_the_map_when_its_ids_are_given() -> None:
    est = np.array([1, 1, 2, 3, 3])
    true = np.array([10, 10, 10, 11, 11])
    assert association_scores(est, true).duplicates == 1  # 2 estimates no true landmark
    s = association_scores(est, true, kept=[1, 3])  # 2 was deleted
    assert (s.duplicates, s.in_map, s.not_in_map, s.estimated_landmarks) == (0, 2, 1, 3)
    # 3 deleted: true landmark 11 has no estimate in the map; 1 and 2 are in it
    s = association_scores(est, true, kept=[1, 2])
    assert (s.duplicates, s.merged, s.in_map, s.not_in_map) == (1, 0, 2, 1)


def test_mcl_reports_its_effective_particles() -> None:
    ds = load_dataset("five-features", seed=0)
    result = run("mcl", ds)
    d = result.output.diagnostics
    s = evaluate(result, ds).scores.signals
    assert s is not None and s.neff_share_mean == d["ess_share_mean"]
    assert 0 < s.neff_share_min <= s.neff_share_mean <= 1  # type: ignore[operator]
    assert s.nis_per_dof is not None and 0.5 < s.nis_per_dof < 2.0
