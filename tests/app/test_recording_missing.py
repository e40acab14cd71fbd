"""Without rerun-sdk a recording stops with the install command, before any run work."""

from __future__ import annotations

import sys

import pytest

from slamkit.app import RunRequest, run_job
from slamkit.errors import InputError


def test_missing_rerun_names_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun now raises ImportError
    with pytest.raises(InputError, match=r"pip install 'slamkit\[rerun\]'"):
        run_job(RunRequest("ekf-slam", "five-features", tmp_path / "out", rerun="run.rrd"))
    assert not (tmp_path / "out").exists()
