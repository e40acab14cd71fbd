"""``slamkit eval ape|rpe``: read two trajectory files, compare them by evo's rules
(:func:`slamkit.eval.pose_error.compare_trajectories`), and write the numbers and figures."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from slamkit._validation import FloatArray
from slamkit.errors import ConfigError, DataNotFoundError, DatasetFormatError
from slamkit.eval.pose_error import Alignment, DeltaUnit, PoseErrorResult, compare_trajectories
from slamkit.io import atomic_folder, read_kitti_matrices, read_tum_matrices, write_json

__all__ = ["EvalFilesReport", "EvalFilesRequest", "TrajectoryFormat", "evaluate_files",
           "read_trajectory"]  # fmt: skip

TrajectoryFormat = Literal["auto", "tum", "kitti"]


def read_trajectory(
    path: Path, fmt: TrajectoryFormat = "auto"
) -> tuple[FloatArray | None, FloatArray]:
    """A trajectory file's stamps (``None`` for KITTI) and SE(3) poses ``(N, 4, 4)``;
    ``"auto"``: KITTI for ``.kitti``/``.txt`` files with 12 numbers a line, else TUM."""
    if not path.is_file():
        raise DataNotFoundError(f"{path}: not found")
    if fmt not in ("auto", "tum", "kitti"):
        raise ConfigError(f"format: expected auto, tum or kitti, got {fmt!r}")
    try:
        if fmt == "auto":
            fmt = "kitti" if _looks_like_kitti(path) else "tum"
        if fmt == "kitti":
            return None, read_kitti_matrices(path)
        return read_tum_matrices(path)
    except UnicodeDecodeError:
        raise DatasetFormatError(
            "not a text file (expected a TUM or KITTI trajectory)", path
        ) from None


def _looks_like_kitti(path: Path) -> bool:
    with path.open(encoding="utf-8") as fh:
        for line in fh:
            text = line.strip()
            if text and not text.startswith("#"):
                return len(text.split()) == 12
    return False


@dataclass(frozen=True)
class EvalFilesRequest:
    """Two trajectory files and how to compare them (see :mod:`slamkit.eval.pose_error`)."""

    reference: Path
    estimate: Path
    kind: Literal["ape", "rpe"] = "ape"
    """Which error the figures show (both are computed and written)."""
    fmt: TrajectoryFormat = "auto"
    alignment: Alignment = "none"
    """None by default, as evo (see :data:`slamkit.eval.pose_error.ALIGNMENTS`)."""
    n_align: int | None = None
    max_diff: float = 0.01
    offset: float = 0.0
    delta: float = 1
    delta_unit: DeltaUnit = "frames"
    all_pairs: bool = False
    pairs_from_reference: bool = False
    out_dir: Path | None = None
    """Where ``metrics.json`` and the figures go (``None``: nothing is written)."""
    plots: bool = True
    overwrite: bool = False


@dataclass(frozen=True)
class EvalFilesReport:
    result: PoseErrorResult
    out_dir: Path | None
    files: tuple[str, ...]


def evaluate_files(request: EvalFilesRequest) -> EvalFilesReport:
    """Read, compare, and (with ``out_dir``) write ``metrics.json`` and the figures."""
    t_ref, ref = read_trajectory(request.reference, request.fmt)
    t_est, est = read_trajectory(request.estimate, request.fmt)
    if (t_ref is None) != (t_est is None):
        raise ConfigError("one file has time stamps (TUM) and the other none (KITTI)")
    result = compare_trajectories(
        ref, est, times_ref=t_ref, times_est=t_est, alignment=request.alignment,
        n_align=request.n_align, max_diff=request.max_diff, offset=request.offset,
        delta=request.delta, all_pairs=request.all_pairs, delta_unit=request.delta_unit,
        pairs_from_reference=request.pairs_from_reference,
    )  # fmt: skip
    if request.out_dir is None:
        return EvalFilesReport(result, None, ())
    with atomic_folder(request.out_dir, overwrite=request.overwrite) as tmp:
        write_json(
            tmp / "metrics.json",
            {"reference": str(request.reference), "estimate": str(request.estimate),
             "max_diff": request.max_diff, "offset": request.offset, **result.as_dict()},
        )  # fmt: skip
        if request.plots:
            from slamkit.viz import save_figure
            from slamkit.viz.pose_error import pose_error_figures

            for name, fig in pose_error_figures(result, request.kind).items():
                save_figure(fig, tmp / name)
        files = tuple(sorted(p.name for p in tmp.iterdir()))
    return EvalFilesReport(result, Path(request.out_dir), files)
