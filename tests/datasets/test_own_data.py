"""Your own data: the landmark CSV layout, a Dataset from arrays that orders same-time events
itself, run_job on a Dataset, and docs/own-data.md's example run as written."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from slamkit.app import RunRequest, run_job
from slamkit.datasets import Control, LandmarkReadings, LandmarkSensorSpec, Odometry
from slamkit.datasets.arrays import landmark_dataset_from_arrays
from slamkit.datasets.assemble import assemble_events
from slamkit.datasets.files import load_data, load_file
from slamkit.datasets.landmark_csv import read_landmark_csv
from slamkit.errors import DatasetFormatError, InputError

DOC = Path(__file__).resolve().parents[2] / "docs" / "own-data.md"


def test_the_docs_example_runs_and_the_csv_run_equals_the_simulated_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    assert len(blocks) == 2
    scope: dict = {}
    for code in blocks:
        exec(compile(code, str(DOC), "exec"), scope)  # the doc's own example
    sim, report, from_arrays = scope["sim"], scope["report"], scope["from_arrays"]
    direct = run_job(RunRequest("ekf-slam", "five-features", tmp_path / "direct", seed=1,
                                plots=False))  # fmt: skip
    # The CSV holds every number to full precision (repr): the same run, the same answer.
    np.testing.assert_allclose(report.result.poses, direct.result.poses, atol=1e-9)
    np.testing.assert_allclose(from_arrays.result.poses, direct.result.poses, atol=1e-9)
    assert report.scores.ate.rmse == pytest.approx(direct.scores.ate.rmse, abs=1e-9)
    assert report.scores.landmarks.rmse < 0.1 and report.scores.landmarks.n_missing == 0
    assert (tmp_path / "results" / "my-run" / "landmarks.csv").exists()
    assert len(report.result.times) == len(direct.result.times) > len(sim.events) // 3


def test_same_time_events_are_ordered_motion_first_whatever_the_input_order():
    z = np.array([[1.0, 0.1]])
    events = [
        LandmarkReadings(1.0, z, np.array([0])),
        Control(1.0, np.array([1.0, 0.0]), 0.5),
        LandmarkReadings(0.5, z, np.array([1])),
        Control(0.5, np.array([1.0, 0.0]), 0.5),
    ]
    out = assemble_events(events)
    assert [(type(e).__name__, e.t) for e in out] == [
        ("Control", 0.5),
        ("LandmarkReadings", 0.5),
        ("Control", 1.0),
        ("LandmarkReadings", 1.0),
    ]
    sensor = LandmarkSensorSpec("range-bearing", np.diag([0.01, 0.001]))
    data = landmark_dataset_from_arrays(
        sensor=sensor,
        reading_times=[1.0, 0.5, 1.0],  # two readings at 1.0, given apart: one scan
        readings=[[2.0, 0.1], [1.0, 0.2], [3.0, -0.1]],
        reading_ids=[4, 5, 6],
        control_times=[0.5, 1.0],
        controls=[[1.0, 0.0], [1.0, 0.1]],
        motion_noise_cov=np.diag([0.01, 0.01]),
    )
    kinds = [(type(e).__name__, e.t) for e in data.events]
    assert kinds == [("Control", 0.5), ("LandmarkReadings", 0.5), ("Control", 1.0),
                     ("LandmarkReadings", 1.0)]  # fmt: skip
    assert data.events[3].ids.tolist() == [4, 6]
    assert [e.dt for e in data.events if isinstance(e, Control)] == [0.5, 0.5]
    with pytest.raises(InputError, match="one of the two"):
        landmark_dataset_from_arrays(sensor=sensor, reading_times=[0.0], readings=[[1.0, 0.0]],
                                     motion_noise_cov=np.eye(2))  # fmt: skip


CSV = """\
# a robot with odometry and a range-bearing sensor, ids unknown
kind,t,a,b,c
reading,1.0,2.0,0.0,
odometry,1.0,1.0,0.0,0.0
odometry,0.0,0.0,0.0,0.0
reading,1.0,3.0,0.5,-1
truth,1.0,1.0,0.0,0.0
truth,0.0,0.0,0.0,0.0
landmark,,3.0,0.0,7
landmark,,3.0,2.0,8
"""


def test_a_csv_with_odometry_and_unknown_ids_reads_in_order(tmp_path):
    p = tmp_path / "robot.csv"
    p.write_text(CSV)
    data = load_data(str(p), options={"sigma_trans": 0.1, "known_map": True})
    assert data.motion is not None and data.motion.source == "odometry"
    assert [type(e) for e in data.events] == [Odometry, Odometry, LandmarkReadings]
    scan = data.events[2]
    np.testing.assert_allclose(scan.z, [[2.0, 0.0], [3.0, 0.5]])
    assert scan.ids.tolist() == [-1, -1] and not data.landmark_sensor.identities
    assert data.known_landmarks is not None and data.known_landmarks.ids.tolist() == [7, 8]
    np.testing.assert_allclose(data.truth.times, [0.0, 1.0])
    assert data.motion.noise_cov[1, 1] == pytest.approx(0.01)
    assert data.provenance.path == str(p.resolve()) and data.name == "robot"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("kind,t,x\n", "expected the header kind,t,a,b,c"),
        ("kind,t,a,b,c\nreading,1,2,x,\ncontrol,1,1,0,1\n", "bad.csv:2: b: not a number"),
        ("kind,t,a,b,c\nsonar,1,2,0,\n", "kind: expected one of"),
        ("kind,t,a,b,c\nreading,1,2,0\n", "expected 5 columns"),
        ("kind,t,a,b,c\ncontrol,1,1,0,1\n", "no reading rows"),
        ("kind,t,a,b,c\nreading,1,2,0,\n", "no control or odometry rows"),
        ("kind,t,a,b,c\nreading,1,2,0,\ncontrol,1,1,0,1\nodometry,1,0,0,0\n", "give one"),
        (
            "kind,t,a,b,c\nreading,1,2,0,\ncontrol,1,1,0,1\nlandmark,,3,0,7\nlandmark,,3,2,7\n",
            "bad.csv:5: landmark id 7 is listed twice (first on line 4)",
        ),
        (
            "kind,t,a,b,c\nreading,1,2,0,\ncontrol,1,1,0,1\nlandmark,,3,0,7.5\n",
            "bad.csv:4: landmark id: expected an integer, got 7.5",
        ),
    ],
)
def test_malformed_csv_files_name_the_file_and_line(tmp_path, text, message):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(DatasetFormatError, match=re.escape(message)):
        read_landmark_csv(p)


def test_a_run_on_a_csv_file_writes_the_standard_files(tmp_path):
    p = tmp_path / "robot.csv"
    p.write_text(CSV)
    report = run_job(RunRequest("ekf-slam", str(p), tmp_path / "o", plots=False,
                                estimator_config={"use_ids": False}))  # fmt: skip
    assert {"trajectory.tum", "groundtruth.tum", "config.json"} <= set(report.files)
    assert load_file(p).name == "robot"
