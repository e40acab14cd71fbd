"""Victoria Park's GPS fused by the online filters — FastSLAM 1.0 and 2.0 and SEIF without and
with the fixes, and EKF-SLAM and UKF-SLAM with them — every estimate scored on the same
held-out fixes (the companion of :mod:`bench_gps_ekf`, which has the landmark graph and
EKF-SLAM's rows).

The loader's ``gps_fuse`` puts every fix but each tenth (the 10th, 20th, …) into the stream;
scores (:func:`slamkit.eval.gps_holdout.holdout_gps_error`) on the held-out fixes that the
GPS track alone does not reject: **aligned** (SE(2) fitted on the other fixes) and **direct**
(none; only meaningful for an estimate in the GPS frame), both at the antenna with the lever
arm the fused landmark graph estimates (``benchmarks/results/gps_ekf.md``: (3.98, 0.41) m).
The readings carry the file's feature index (``identities``), so every filter sees the same
association. FastSLAM runs with the preset ``victoria-park-fastslam`` (what ``slamkit run
fastslam2 --data victoria-park`` lays under the config) and 100 particles. Each
configuration runs once (seed 0), the filters interleaved; times are whole runs (the
pipeline's ``run``). Needs the real data (``SLAMKIT_DATA``).

    python benchmarks/bench_gps_filters.py
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from _common import Record, write_results
from slamkit.app.presets import get_preset
from slamkit.datasets import find_data_root, load_dataset
from slamkit.datasets.gps_split import holdout_mask
from slamkit.eval.gps_holdout import holdout_gps_error
from slamkit.pipeline import run
from slamkit.slam.ekf_slam import EkfSlamConfig
from slamkit.slam.fastslam import FastSlamConfig
from slamkit.slam.seif import SeifConfig
from slamkit.slam.ukf_slam import UkfSlamConfig

HOLDOUT = 10
ARM = (3.98, 0.41)  # [m] the fused landmark graph's lever arm (bench_gps_ekf)
FASTSLAM = {**get_preset("victoria-park-fastslam").settings, "n_particles": 100}

# (label, estimator, config, fused)
CASES: tuple[tuple[str, str, Any, bool], ...] = (
    ("FastSLAM 1.0 without GPS", "fastslam1", FastSlamConfig(**FASTSLAM), False),
    ("FastSLAM 1.0 + GPS", "fastslam1", FastSlamConfig(**FASTSLAM, gps_lever_arm=ARM), True),
    ("FastSLAM 2.0 without GPS", "fastslam2", FastSlamConfig(**FASTSLAM), False),
    ("FastSLAM 2.0 + GPS", "fastslam2", FastSlamConfig(**FASTSLAM, gps_lever_arm=ARM), True),
    ("EKF-SLAM + GPS", "ekf-slam", EkfSlamConfig(gps_lever_arm=ARM), True),
    ("UKF-SLAM + GPS", "ukf-slam", UkfSlamConfig(gps_lever_arm=ARM), True),
    ("SEIF without GPS", "seif", SeifConfig(), False),
    ("SEIF + GPS", "seif", SeifConfig(gps_lever_arm=ARM), True),
)


def main() -> str:
    root = find_data_root()
    if root is None:
        return "bench_gps_filters: skipped (no real data; set SLAMKIT_DATA)"
    plain = load_dataset("victoria-park", options={"identities": True}, data_root=root)
    fused_opts = {"identities": True, "gps_fuse": True, "gps_holdout_every": HOLDOUT}
    fusing = load_dataset("victoria-park", options=fused_opts, data_root=root)
    t, xy = plain.truth.position_times, plain.truth.positions
    assert t is not None and xy is not None
    held = holdout_mask(t.shape[0], HOLDOUT)
    load_before = os.getloadavg()[0]
    rows, records, times = [], [], {}
    for label, key, config, fused in CASES:
        t0 = time.perf_counter()
        res = run(key, fusing if fused else plain, config=config, seed=0)
        sec = time.perf_counter() - t0
        times[label] = sec
        s = holdout_gps_error(res.times, res.poses, t, xy, held, lever_arm=ARM)
        d = res.output.diagnostics
        lm = res.output.landmarks
        n_lm = -1 if lm is None else int(lm.landmarks.ids.shape[0])
        gps = "—"
        if fused:
            gps = (f"{d['gps_refused']} of {d['gps_fixes']} refused, {d['gps_aligning']} to "
                   f"move into the GPS frame, {d['gps_fused']} fused")  # fmt: skip
        direct = f"{s.direct_rmse:.2f} | {s.direct_median:.2f}" if fused else "— | —"
        rows.append(f"| {label} | {sec:.1f} | {s.rmse:.2f} | {s.median:.2f} | {direct} | "
                    f"{n_lm} | {gps} | {len(res.output.warnings)} |")  # fmt: skip
        assert np.isfinite(s.rmse)
    for v in ("FastSLAM 1.0", "FastSLAM 2.0", "SEIF"):
        with_gps, without = f"{v} + GPS", f"{v} without GPS"
        records.append(Record(f"{with_gps}: whole run", times[with_gps], without, times[without]))
    records.append(Record("FastSLAM 2.0 + GPS: whole run", times["FastSLAM 2.0 + GPS"],
                          "EKF-SLAM + GPS", times["EKF-SLAM + GPS"]))  # fmt: skip
    table = "\n".join(
        [
            "| estimate | time [s] | held-out RMSE, aligned [m] | median, aligned [m] | "
            "direct RMSE [m] | direct median [m] | landmarks | GPS fixes | warnings |",
            "|---|---:|---:|---:|---:|---:|---:|---|---:|",
            *rows,
        ]
    )
    notes = (
        f"Victoria Park, whole run, readings with the file's feature index; {t.shape[0]} "
        f"fixes, every {HOLDOUT}th held out ({int(held.sum())}), scored at the lever arm "
        f"{ARM} m (the fused graph's). FastSLAM settings: {FASTSLAM}. One run each, seed 0, "
        f"interleaved. Load average (1 min) {load_before:.1f} before, "
        f"{os.getloadavg()[0]:.1f} after, on {os.cpu_count()} CPUs (other jobs share them: "
        f"times are noisy).\n\n{table}"
    )
    return write_results("gps_filters", records, notes=notes)


if __name__ == "__main__":
    print(main())
