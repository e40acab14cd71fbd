"""Where a data set came from: the typed Provenance record, read by the app layer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slamkit.app.runconfig import dataset_table
from slamkit.datasets import load_dataset
from slamkit.datasets.files import load_file
from slamkit.datasets.provenance import Provenance
from slamkit.errors import InputError


def _dpslam_log(path: Path, scans: int = 3) -> Path:
    lines = []
    for k in range(scans):
        lines.append(f"Odometry {0.1 * k} 0.0 0.0")
        lines.append("Laser 181 " + " ".join(["2.5"] * 181))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_a_path_and_its_reader_go_together_and_options_are_copied() -> None:
    with pytest.raises(InputError, match="path and its reader"):
        Provenance(path="/x.log")
    options = {"max_range": 8.0}
    record = Provenance(options=options)
    options["max_range"] = 1.0
    assert record.options == {"max_range": 8.0}
    read = record.read_from("/x.log", "dpslam", registered_as="loop5")
    assert (read.path, read.reader, read.registered_as, read.options) == (
        "/x.log",
        "dpslam",
        "loop5",
        {"max_range": 8.0},
    )


def test_a_file_read_by_path_records_its_path_reader_and_options(tmp_path: Path) -> None:
    path = _dpslam_log(tmp_path / "mine.log")
    ds = load_file(path, {"max_range": 3.0})
    assert ds.provenance.path == str(path.resolve())
    assert ds.provenance.reader == "dpslam"
    assert ds.provenance.options is not None and ds.provenance.options["max_range"] == 3.0
    assert not {"path", "reader", "config", "registered_as"} & set(ds.metadata)
    table = dataset_table(ds)
    assert table["path"] == str(path.resolve()) and table["reader"] == "dpslam"
    assert table["max_range"] == 3.0 and table["scan_period"] == 1.0
    assert table["name"] == "mine"


def test_with_provenance_shares_the_events_and_copies_the_metadata(tmp_path: Path) -> None:
    ds = load_file(_dpslam_log(tmp_path / "a.log"))
    other = ds.with_provenance(Provenance(options={"k": 1}))
    assert other.events is ds.events and other.provenance.options == {"k": 1}
    other.metadata["note"] = "mine"
    assert "note" not in ds.metadata
    np.testing.assert_array_equal(other.laser.beam_angles, ds.laser.beam_angles)  # type: ignore[union-attr]


def test_a_simulated_set_records_its_options_and_no_path() -> None:
    ds = load_dataset("five-features", seed=1, options={"speed": 0.8})
    assert ds.provenance.path is None and ds.provenance.reader is None
    assert ds.provenance.options is not None and ds.provenance.options["speed"] == 0.8
    table = dataset_table(ds)
    assert "path" not in table and table["speed"] == 0.8
