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

The YAML written here is the flat ``key: value`` subset map files use (no YAML library
needed). Reading (``trinary``, ``scale`` and ``raw`` modes, ``P5`` and ``P2`` images, the quirks
read past and said) is :mod:`slamkit.io.rosmap_read`; :func:`read_ros_map` is re-exported here.
"""

from __future__ import annotations

import os
import uuid
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slamkit.errors import InputError
from slamkit.io.rosmap_read import read_ros_map
from slamkit.mapping.quality import FREE_THRESHOLD, OCCUPIED_THRESHOLD, check_thresholds
from slamkit.maps import OccupancyGrid

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
