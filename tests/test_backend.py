"""The one seam of the compiled-or-NumPy choice (:mod:`slamkit.backend`): a pair runs the
form of the backend in force, ``SEAM.use`` holds a choice for its block alone (nested, on
an error, in its own thread), and the default is numba exactly when it is importable."""

from __future__ import annotations

import threading

import pytest

from slamkit import backend
from slamkit.backend import AVAILABLE, SEAM, Backend, KernelSeam
from slamkit.errors import ConfigError


def _compiled(x: int) -> str:
    return f"compiled {x}"


def _oracle(x: int) -> str:
    return f"oracle {x}"


def test_a_pair_runs_the_form_of_the_backend_in_force() -> None:
    seam = KernelSeam(Backend.NUMPY)
    both = seam.pair(compiled=_compiled, oracle=_oracle)
    assert both(1) == "oracle 1"
    assert both.__name__ == "_oracle"
    numba_seam = KernelSeam(Backend.NUMBA)
    assert numba_seam.pair(compiled=_compiled, oracle=_oracle)(x=2) == "compiled 2"
    with numba_seam.use(Backend.NUMPY):
        assert numba_seam.pair(compiled=_compiled, oracle=_oracle)(3) == "oracle 3"


def test_the_default_is_numba_exactly_when_it_imports() -> None:
    assert SEAM.default is (Backend.NUMBA if AVAILABLE else Backend.NUMPY)
    assert SEAM.backend is SEAM.default


def test_use_nests_and_restores_after_an_error() -> None:
    seam = KernelSeam(Backend.NUMPY)
    with pytest.raises(RuntimeError), seam.use(Backend.NUMPY):
        assert seam.backend is Backend.NUMPY
        raise RuntimeError
    assert seam.backend is Backend.NUMPY
    if AVAILABLE:
        with seam.use(Backend.NUMBA):
            assert seam.backend is Backend.NUMBA
            with seam.use(Backend.NUMPY):
                assert seam.backend is Backend.NUMPY
            assert seam.backend is Backend.NUMBA
        assert seam.backend is Backend.NUMPY


def test_a_choice_stays_in_its_thread() -> None:
    seam = KernelSeam(Backend.NUMBA)
    seen: list[Backend] = []
    with seam.use(Backend.NUMPY):
        worker = threading.Thread(target=lambda: seen.append(seam.backend))
        worker.start()
        worker.join()
        assert seam.backend is Backend.NUMPY
    assert seen == [Backend.NUMBA]


def test_numba_without_numba_is_a_config_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(backend, "AVAILABLE", False)
    with pytest.raises(ConfigError, match="numba is not installed"), SEAM.use(Backend.NUMBA):
        pass
    assert SEAM.backend is SEAM.default
