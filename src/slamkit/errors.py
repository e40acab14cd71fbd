"""The one exception tree of slamkit.

Every error slamkit raises on purpose derives from :class:`SlamkitError`, so callers (and the
CLI) can catch "a known problem with the input" in one place. Input errors also derive from
:class:`ValueError`, so code that already catches ``ValueError`` keeps working.
"""

from __future__ import annotations

from pathlib import Path

__all__ = [
    "ConfigError",
    "ConvergenceError",
    "CovarianceError",
    "DataNotFoundError",
    "DatasetFormatError",
    "FetchError",
    "GeometryError",
    "InputError",
    "MatchError",
    "NonFiniteError",
    "ShapeError",
    "SlamkitError",
    "UnknownNameError",
]


class SlamkitError(Exception):
    """Base class of every error slamkit raises deliberately."""


class InputError(SlamkitError, ValueError):
    """An argument does not have the form or the values that were expected."""


class ShapeError(InputError):
    """An array has the wrong number of dimensions or the wrong size along one."""


class NonFiniteError(InputError):
    """An array holds NaN or infinity where finite numbers were expected."""


class CovarianceError(InputError):
    """A covariance (or information) matrix is not symmetric positive (semi-)definite."""


class GeometryError(InputError):
    """The geometry of a problem does not determine its answer (degenerate configuration)."""


class ConfigError(InputError):
    """A configuration value is unknown, of the wrong type or out of range."""


class UnknownNameError(SlamkitError, KeyError):
    """A name (estimator, dataset, scenario) is not registered."""

    def __init__(self, kind: str, name: str, known: list[str] | tuple[str, ...]) -> None:
        self.kind = kind
        self.name = name
        self.known = tuple(known)
        super().__init__(f"unknown {kind} {name!r}; known: {', '.join(self.known) or '(none)'}")

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0])


class DataNotFoundError(SlamkitError, FileNotFoundError):
    """A data file or folder that a loader needs is not there."""


class FetchError(SlamkitError, OSError):
    """A data file could not be fetched: the connection failed or dropped, the server said
    no, or what arrived does not match the file's size and SHA-256. Nothing of that file is
    left behind; ``url`` and ``path`` (its target) say which."""

    def __init__(self, message: str, url: str | None = None, path: str | Path | None = None):
        self.url = url
        self.path = None if path is None else Path(path)
        super().__init__(message)

    def __str__(self) -> str:  # OSError would format (errno, strerror)
        return str(self.args[0])


class DatasetFormatError(SlamkitError, ValueError):
    """A data file does not follow its format; names the file and the line."""

    def __init__(self, message: str, path: str | Path | None = None, line: int | None = None):
        self.path = None if path is None else Path(path)
        self.line = line
        where = ""
        if self.path is not None:
            where = f"{self.path}"
            if line is not None:
                where += f":{line}"
            where += ": "
        super().__init__(where + message)


class ConvergenceError(SlamkitError, RuntimeError):
    """An estimator diverged or a solver failed; says at which step or iteration."""

    def __init__(self, message: str, step: int | None = None) -> None:
        self.step = step
        super().__init__(message if step is None else f"step {step}: {message}")


class MatchError(SlamkitError, RuntimeError):
    """A scan matcher could not register two scans (or a scan and a map): too few
    correspondences, geometry that leaves a direction unconstrained (a featureless corridor),
    an empty scan. ``reason`` is a short machine-readable code (``"too_few_points"``,
    ``"too_few_correspondences"``, ``"degenerate"``, ``"no_convergence"``, ``"low_score"``)."""

    def __init__(self, message: str, reason: str) -> None:
        self.reason = reason
        super().__init__(message)
