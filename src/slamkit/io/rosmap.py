"""Occupancy grids in the ROS ``map_server`` format: a PGM image and a YAML description.

The PGM is binary greyscale (``P5``, 8 bit, maxval 255), one pixel per cell, written in
*trinary* form: 0 (black) occupied, 255 (white) free, 128 (mid grey) unknown. Image rows run
downwards, grid rows upwards (:mod:`slamkit.maps.types`), so the first image row is the
grid's last row. The YAML file says how to read it back::

    image: map.pgm
    resolution: 0.05          # metres per pixel
    origin: [x, y, 0.0]       # world pose of the lower-left pixel's lower-left corner
    negate: 0
    occupied_thresh: 0.65
    free_thresh: 0.35
    mode: trinary

``map_server`` turns a pixel value ``v`` into ``p = (255 - v) / 255`` (``v / 255`` with
``negate: 1``) and calls the cell occupied if ``p > occupied_thresh``, free if
``p < free_thresh``, else unknown — which maps 0 (p = 1) → occupied, 255 (p = 0) → free and
128 (p = 0.498) → unknown. :func:`read_ros_map` does the same, so a grid written by
:func:`write_ros_map` reads back cell for cell as 1 (occupied), 0 (free) or 0.5 (unknown).

**One threshold convention.** The thresholds written into the YAML are the ones the cells
were classified with — by default :data:`~slamkit.mapping.quality.OCCUPIED_THRESHOLD` and
:data:`~slamkit.mapping.quality.FREE_THRESHOLD`, the same numbers as the map-quality report
(``quality.json``) — so the YAML describes the map it comes with. ROS's own ``map_saver``
writes unknown cells as 205 and ``free_thresh: 0.196``, a number chosen only so that its
grey decodes (p = 50/255 = 0.196, not below 0.196) as unknown; with ``free_thresh: 0.35``
that grey would read back as free, hence the mid grey 128 here, which decodes as unknown
under any thresholds with ``free < 0.498 < occupied``. The comparisons differ only at the
thresholds themselves (``p >= occupied`` and ``p <= free`` in slamkit, strict in
``map_server``), which no trinary pixel decodes to.

The YAML written and read here is the flat ``key: value`` subset map files use (no YAML
library needed); an origin with a non-zero yaw is rejected, since :class:`OccupancyGrid` has
no rotation.
"""

from __future__ import annotations

import math
import os
import re
import uuid
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slamkit.errors import DatasetFormatError, InputError
from slamkit.mapping.quality import FREE_THRESHOLD, OCCUPIED_THRESHOLD, check_thresholds
from slamkit.maps import UNKNOWN, OccupancyGrid

__all__ = ["FREE_PIXEL", "OCCUPIED_PIXEL", "UNKNOWN_PIXEL", "read_ros_map", "write_ros_map"]

OCCUPIED_PIXEL = 0
FREE_PIXEL = 255
UNKNOWN_PIXEL = 128
"""Mid grey: ``p = (255 - 128) / 255 = 0.498``, unknown between the thresholds (module
docstring); also the grey of an unknown cell (p = 0.5) in the PNG of :mod:`slamkit.viz.maps`."""
_UNKNOWN_P = (255 - UNKNOWN_PIXEL) / 255.0


def _atomic_write(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def trinary_pixels(
    grid: OccupancyGrid,
    occupied_threshold: float = OCCUPIED_THRESHOLD,
    free_threshold: float = FREE_THRESHOLD,
) -> NDArray[np.uint8]:
    """The image ``(rows, cols)`` uint8 of ``grid``, top row first: 0 where
    ``p >= occupied_threshold``, 255 where ``p <= free_threshold``, :data:`UNKNOWN_PIXEL`
    elsewhere. The thresholds must be ones a ``map_server`` can decode these three pixels
    with: ``0 < free < 0.498 < occupied < 1``."""
    check_thresholds(occupied_threshold, free_threshold)
    if not (0.0 < free_threshold < _UNKNOWN_P < occupied_threshold < 1.0):
        raise InputError(
            f"thresholds: a trinary map needs 0 < free < {_UNKNOWN_P:.3f} < occupied < 1 "
            f"(so that map_server decodes its three pixel values), got free {free_threshold}, "
            f"occupied {occupied_threshold}"
        )
    img = np.full(grid.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    img[grid.prob <= free_threshold] = FREE_PIXEL
    img[grid.prob >= occupied_threshold] = OCCUPIED_PIXEL
    return np.ascontiguousarray(img[::-1])


def write_ros_map(
    grid: OccupancyGrid,
    pgm_path: str | Path,
    yaml_path: str | Path | None = None,
    *,
    occupied_threshold: float = OCCUPIED_THRESHOLD,
    free_threshold: float = FREE_THRESHOLD,
) -> tuple[Path, Path]:
    """Write ``grid`` as ``pgm_path`` and its YAML (default: the PGM path with ``.yaml``).

    Cells with ``p >= occupied_threshold`` become occupied pixels, cells with
    ``p <= free_threshold`` free pixels, the rest unknown (:func:`trinary_pixels`); the YAML
    records these same thresholds. Both files are written atomically. Returns the two paths.
    """
    pgm = Path(pgm_path)
    yml = Path(yaml_path) if yaml_path is not None else pgm.with_suffix(".yaml")
    img = trinary_pixels(grid, occupied_threshold, free_threshold)
    rows, cols = img.shape
    header = f"P5\n# slamkit occupancy grid, {grid.resolution!r} m per pixel\n{cols} {rows}\n255\n"
    x0, y0 = (float(v) for v in grid.origin_xy)
    image_ref = os.path.relpath(pgm, yml.parent) if pgm.parent != yml.parent else pgm.name
    text = (
        f"image: {image_ref}\n"
        f"resolution: {float(grid.resolution)!r}\n"
        f"origin: [{x0!r}, {y0!r}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {float(occupied_threshold)!r}\n"
        f"free_thresh: {float(free_threshold)!r}\n"
        "mode: trinary\n"
    )
    pgm.parent.mkdir(parents=True, exist_ok=True)
    yml.parent.mkdir(parents=True, exist_ok=True)
    _atomic_write(pgm, header.encode("ascii") + img.tobytes())
    _atomic_write(yml, text.encode("utf-8"))
    return pgm, yml


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------


def _read_yaml(path: Path) -> dict[str, tuple[str, int]]:
    """``key -> (raw value, line)`` of a flat ``key: value`` file (comments dropped)."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise DatasetFormatError(f"cannot read the map description ({exc.strerror})", path) from exc
    out: dict[str, tuple[str, int]] = {}
    for number, line in enumerate(lines, start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        key, sep, value = body.partition(":")
        if not sep or not key.strip():
            raise DatasetFormatError(f"expected 'key: value', got {line.strip()!r}", path, number)
        out[key.strip()] = (value.strip().strip("'\""), number)
    return out


def _number(fields: dict[str, tuple[str, int]], key: str, path: Path, default: float) -> float:
    if key not in fields:
        return default
    raw, line = fields[key]
    try:
        value = float(raw)
    except ValueError:
        raise DatasetFormatError(f"{key}: expected a number, got {raw!r}", path, line) from None
    if not math.isfinite(value):
        raise DatasetFormatError(f"{key}: expected a finite number, got {raw!r}", path, line)
    return value


def _read_pgm(path: Path) -> NDArray[np.uint8]:
    """A binary 8-bit PGM (``P5``, maxval <= 255) as ``(rows, cols)`` uint8, top row first."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DatasetFormatError(f"cannot read the map image ({exc.strerror})", path) from exc
    # Header: magic, width, height, maxval, separated by whitespace and '#' comments.
    tokens: list[bytes] = []
    pos = 0
    token = re.compile(rb"\s*(?:#[^\n]*\n\s*)*(\S+)")
    while len(tokens) < 4:
        m = token.match(data, pos)
        if m is None:
            raise DatasetFormatError("truncated PGM header", path)
        tokens.append(m.group(1))
        pos = m.end()
    if tokens[0] != b"P5":
        raise DatasetFormatError(f"expected a binary PGM ('P5'), got {tokens[0]!r}", path)
    try:
        cols, rows, maxval = (int(t) for t in tokens[1:])
    except ValueError:
        raise DatasetFormatError(
            "PGM header: width, height and maxval must be integers", path
        ) from None
    if cols < 1 or rows < 1 or not 0 < maxval <= 255:
        raise DatasetFormatError(
            f"PGM header: expected an 8-bit image of at least 1 × 1, got {cols} × {rows}, "
            f"maxval {maxval}",
            path,
        )
    pixels = data[pos + 1 :]  # exactly one whitespace byte ends the header
    if len(pixels) != rows * cols:
        raise DatasetFormatError(
            f"PGM: expected {rows * cols} pixel bytes for {cols} × {rows}, got {len(pixels)}",
            path,
        )
    img = np.frombuffer(pixels, dtype=np.uint8).reshape(rows, cols)
    if maxval != 255:
        img = np.round(img.astype(np.float64) * (255.0 / maxval)).astype(np.uint8)
    return img


def read_ros_map(yaml_path: str | Path) -> OccupancyGrid:
    """Read a ``map_server`` YAML and its image into an :class:`OccupancyGrid` of 1
    (occupied), 0 (free) and :data:`~slamkit.maps.UNKNOWN` (module docstring)."""
    yml = Path(yaml_path)
    fields = _read_yaml(yml)
    if "image" not in fields:
        raise DatasetFormatError("missing 'image'", yml)
    if "resolution" not in fields:
        raise DatasetFormatError("missing 'resolution'", yml)
    resolution = _number(fields, "resolution", yml, math.nan)
    if not resolution > 0:
        raise DatasetFormatError(
            f"resolution: expected a number > 0, got {resolution}", yml, fields["resolution"][1]
        )
    origin_raw, origin_line = fields.get("origin", ("[0, 0, 0]", 0))
    parts = origin_raw.strip("[]").split(",")
    try:
        origin = [float(v) for v in parts]
    except ValueError:
        origin = []
    if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
        raise DatasetFormatError(
            f"origin: expected [x, y, yaw], got {origin_raw!r}", yml, origin_line
        )
    if origin[2] != 0.0:
        raise DatasetFormatError(
            f"origin: a rotated map (yaw {origin[2]}) is not supported", yml, origin_line
        )
    negate = int(_number(fields, "negate", yml, 0.0))
    occ_t = _number(fields, "occupied_thresh", yml, OCCUPIED_THRESHOLD)
    free_t = _number(fields, "free_thresh", yml, FREE_THRESHOLD)
    image = Path(fields["image"][0])
    img = _read_pgm(image if image.is_absolute() else yml.parent / image)
    v = img[::-1].astype(np.float64)  # grid rows run upwards
    p = v / 255.0 if negate else (255.0 - v) / 255.0
    prob = np.full(v.shape, UNKNOWN)
    prob[p > occ_t] = 1.0
    prob[p < free_t] = 0.0
    return OccupancyGrid(prob, resolution, np.array(origin[:2]))
