"""The defects the fuzz suite found, each pinned by a hand-made case (file, line, value)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from fuzzcases import write_files
from fuzztargets import isam_landmarks_target, plaza_target, snapshots_target

from slamkit.datasets.isam_landmarks import CITYTREES_FILES, load_citytrees10000
from slamkit.datasets.mrclam_snapshots import GROUNDTRUTH_FILE, load_mrclam_snapshots
from slamkit.datasets.plaza import DR_FILE, load_plaza1
from slamkit.errors import DatasetFormatError
from slamkit.io.posegraph import read_graph
from slamkit.io.tum import read_tum

TUM_OK = "1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0.7071067811865476 0.7071067811865476\n"


@pytest.mark.parametrize(
    ("row", "line", "message"),
    [
        (b"3.0 1 0 0 0 0 \xff 1\n", 3, "not UTF-8"),
        (b"3.0 nan 0 0 0 0 0 1\n", 3, "finite"),
        (b"3.0 inf 0 0 0 0 0 1\n", 3, "finite"),
        ("3.0 \u0661 0 0 0 0 0 1\n".encode(), 3, "ASCII"),
        (b"3.0 1 0 0 0 0 0 0\n", 3, "quaternion"),
    ],
)
def test_tum_rows_that_are_not_poses_name_their_line(tmp_path: Path, row, line, message) -> None:
    path = tmp_path / "t.tum"
    path.write_bytes(TUM_OK.encode() + row)
    with pytest.raises(DatasetFormatError, match=message) as info:
        read_tum(path)
    assert info.value.line == line and info.value.path == path


def test_tum_huge_quaternion_components_give_the_yaw_without_overflow(tmp_path: Path) -> None:
    path = tmp_path / "t.tum"
    c = math.cos(0.3) * 1e300
    s = math.sin(0.3) * 1e300
    path.write_text(f"{TUM_OK}3.0 1 2 0 0 0 {s!r} {c!r}\n")
    times, poses = read_tum(path)
    np.testing.assert_allclose(times, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(poses[:, 2], [0.0, math.pi / 2, 0.6], atol=1e-12)


@pytest.mark.parametrize("fix", ["FIX 9223372036854775808", "FIX 1 \u0661", "FIX -3"])
def test_a_fix_id_out_of_range_or_not_ascii_is_a_line_error(tmp_path: Path, fix: str) -> None:
    path = tmp_path / "g.g2o"
    path.write_text(
        f"VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n{fix}\n"
    )
    with pytest.raises(DatasetFormatError, match="non-negative integer id") as info:
        read_graph(path)
    assert info.value.line == 4


def _citytrees(tmp_path: Path, edit) -> DatasetFormatError:
    files = dict(isam_landmarks_target().files)
    lines = files[CITYTREES_FILES[0]].decode().splitlines()
    files[CITYTREES_FILES[0]] = ("\n".join(edit(lines)) + "\n").encode()
    write_files(tmp_path, files)
    with pytest.raises(DatasetFormatError) as info:
        load_citytrees10000({}, seed=0, data_root=tmp_path)
    return info.value


def test_citytrees_mismatch_names_the_line_of_the_edited_file(tmp_path: Path) -> None:
    # A duplicated EDGE2 line (line 2 copied after itself) in the noisy file: the error names
    # that file at the copy (line 3), and the truth file's line it disagrees with.
    err = _citytrees(tmp_path, lambda ls: [*ls[:2], ls[1], *ls[2:]])
    assert err.path is not None and err.path.name == "cityTrees10000.txt"
    assert err.line == 3 and "cityTrees10000_groundtruth.txt" in str(err)
    # An extra LANDMARK line at the end: named at its own line, 16.
    err = _citytrees(tmp_path, lambda ls: [*ls, "LANDMARK 2 12 1 1 10 0 10"])
    assert err.path is not None and err.path.name == "cityTrees10000.txt" and err.line == 16


def test_citytrees_non_utf8_names_the_line(tmp_path: Path) -> None:
    files = dict(isam_landmarks_target().files)
    files[CITYTREES_FILES[0]] = files[CITYTREES_FILES[0]].replace(b"EDGE2 2 3", b"EDGE2 \xff 3")
    write_files(tmp_path, files)
    with pytest.raises(DatasetFormatError, match="not UTF-8") as info:
        load_citytrees10000({}, seed=0, data_root=tmp_path)
    assert info.value.line == 4  # line 3 is a LANDMARK line


def test_snapshot_dangling_experiment_names_both_files(tmp_path: Path) -> None:
    files = dict(snapshots_target().files)
    lines = files[GROUNDTRUTH_FILE].decode().splitlines()
    files[GROUNDTRUTH_FILE] = ("\n".join([lines[0], *lines[2:]]) + "\n").encode()  # no exp 1
    write_files(tmp_path, files)
    with pytest.raises(DatasetFormatError, match="experiment 1 is not in the ground truth") as info:
        load_mrclam_snapshots({}, data_root=tmp_path)
    assert info.value.line == 2 and "mrclam1_groundtruth.csv" in str(info.value)


def test_plaza_odometry_overflow_names_the_line(tmp_path: Path) -> None:
    files = dict(plaza_target().files)
    lines = files[DR_FILE].decode().splitlines()
    fields = lines[3].split()
    fields[1] = "1.7e308"  # finite, but the rate over 0.2 s is not
    lines[3] = " ".join(fields)
    files[DR_FILE] = ("\n".join(lines) + "\n").encode()
    write_files(tmp_path, files)
    with pytest.raises(DatasetFormatError, match="overflows as a rate") as info:
        load_plaza1({}, seed=0, data_root=tmp_path)
    assert info.value.line == 4 and info.value.path == tmp_path / DR_FILE
