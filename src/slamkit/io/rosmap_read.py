"""Reading a ROS ``map_server`` map: the YAML description and its PGM image.

The YAML is the flat file ``map_server`` reads (keys in any order, ``#`` comments)::

    image: map.pgm              # relative to the YAML's folder, or absolute
    resolution: 0.05            # metres per pixel
    origin: [-12.2, -7.5, 0.0]  # x, y [m] of the lower-left pixel's corner, yaw [rad]
    negate: 0                   # 1: white is occupied
    occupied_thresh: 0.65
    free_thresh: 0.196
    mode: trinary               # or scale, raw (optional; trinary by default)

``image`` and ``resolution`` are required; the others default to the values above (``origin``
to ``[0, 0, 0]``, the thresholds to slamkit's :data:`~slamkit.maps.OCCUPIED_THRESHOLD` and
:data:`~slamkit.maps.FREE_THRESHOLD`). No YAML library is needed for this flat subset: the
parser here is strict about what it accepts (one ``key: value`` per line, the origin as a flow
list ``[x, y, yaw]``) and every refusal is a :class:`~slamkit.errors.DatasetFormatError`
naming the file and the line.

**Pixels to occupancy**, as ``map_server`` decodes them. A pixel value ``v`` (0..255, scaled
from the image's maxval) gives ``p = (255 - v) / 255``, or ``v / 255`` with ``negate: 1``:

* ``trinary``: occupied (1) if ``p > occupied_thresh``, free (0) if ``p < free_thresh``, else
  unknown (:data:`~slamkit.maps.UNKNOWN`). ROS's ``map_saver`` writes unknown cells as 205 with
  ``free_thresh: 0.196``: ``p = 50/255 = 0.19608`` is not below it, so they read as unknown;
  slamkit's own files use 128 (:mod:`slamkit.io.rosmap`);
* ``scale``: as trinary at the two ends; in between the occupancy ``99 (p - free) / (occupied
  - free)`` percent, read as that probability. A PGM has no alpha channel, so no pixel is
  unknown in this mode (a ``map_saver`` grey becomes nearly free, as it does in
  ``map_server``);
* ``raw``: the pixel value itself is the occupancy in percent (0..100; ``negate`` does not
  apply); any other value is unknown.

**Quirks read past, and said** (:attr:`RosMapReading.notes`): an origin with a non-zero yaw
is read unrotated — :class:`~slamkit.maps.OccupancyGrid` has no rotation, and ROS's own
localizers and costmaps also place the grid by the origin's x and y only; keys this reader
does not know are ignored; bytes after the last pixel of a binary PGM are ignored. The image
must be a PGM (``P5`` binary or ``P2`` text, maxval at most 255): a PNG map is refused with a
message saying so.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slamkit.errors import DatasetFormatError
from slamkit.maps import FREE_THRESHOLD, OCCUPIED_THRESHOLD, UNKNOWN, OccupancyGrid

__all__ = [
    "MAP_KEYS",
    "MODES",
    "RosMapReading",
    "decode_pixels",
    "read_pgm",
    "read_ros_map",
    "read_ros_map_reading",
]

MODES = ("trinary", "scale", "raw")
"""The ``mode`` values ``map_server`` knows."""
MAP_KEYS = (
    "image",
    "resolution",
    "origin",
    "negate",
    "occupied_thresh",
    "free_thresh",
    "mode",
)
"""The YAML keys read; others are ignored with a note."""

_Fields = dict[str, tuple[str, int]]


@dataclass(frozen=True)
class RosMapReading:
    """A map read by :func:`read_ros_map_reading`: the ``grid``, the ``mode`` it was decoded
    with, the image file, and what was read past (module docstring), one line each."""

    grid: OccupancyGrid
    mode: str
    image: Path
    notes: tuple[str, ...] = ()


def _read_yaml(path: Path) -> _Fields:
    """``key -> (raw value, line)`` of a flat ``key: value`` file (comments dropped)."""
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise DatasetFormatError(f"cannot read the map description ({exc.strerror})", path) from exc
    except UnicodeDecodeError as exc:
        bad_line = path.read_bytes()[: exc.start].count(b"\n") + 1
        raise DatasetFormatError("expected UTF-8 text", path, bad_line) from None
    out: _Fields = {}
    for number, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body or body in ("---", "..."):  # YAML document markers
            continue
        key, sep, value = body.partition(":")
        key = key.strip().strip("'\"")
        if not sep or not key or not value.strip():
            raise DatasetFormatError(
                f"expected 'key: value' (the flat map_server YAML), got {line.strip()!r}",
                path,
                number,
            )
        if key in out:
            raise DatasetFormatError(
                f"{key}: given twice (first on line {out[key][1]})", path, number
            )
        value = value.strip()
        if len(value) >= 2 and value[0] == value[-1] and value[0] in "'\"":
            value = value[1:-1]
        out[key] = (value, number)
    if not out:
        raise DatasetFormatError("empty map description (expected image: and resolution:)", path)
    return out


def _number(fields: _Fields, key: str, path: Path, default: float) -> float:
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


def _origin(fields: _Fields, path: Path) -> tuple[float, float, float, int]:
    raw, line = fields.get("origin", ("[0, 0, 0]", 0))
    text = raw.strip()
    values: list[float] = []
    if text.startswith("[") and text.endswith("]"):
        try:
            values = [float(v) for v in text[1:-1].split(",")]
        except ValueError:
            values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise DatasetFormatError(
            f"origin: expected [x, y, yaw] (three finite numbers), got {raw!r}", path, line
        )
    return values[0], values[1], values[2], line


@dataclass(frozen=True)
class _Decoding:
    mode: str
    negate: bool
    occupied: float
    free: float


def _decoding(fields: _Fields, path: Path) -> _Decoding:
    negate_raw = fields.get("negate", ("0", 0))
    if negate_raw[0].lower() not in ("0", "1", "true", "false"):
        raise DatasetFormatError(
            f"negate: expected 0 or 1, got {negate_raw[0]!r}", path, negate_raw[1]
        )
    occupied = _number(fields, "occupied_thresh", path, OCCUPIED_THRESHOLD)
    free = _number(fields, "free_thresh", path, FREE_THRESHOLD)
    if not 0.0 <= free < occupied <= 1.0:
        line = fields.get("free_thresh", fields.get("occupied_thresh", ("", None)))[1]
        raise DatasetFormatError(
            f"free_thresh, occupied_thresh: expected 0 <= free_thresh < occupied_thresh <= 1, "
            f"got {free}, {occupied}",
            path,
            line,
        )
    mode_raw, mode_line = fields.get("mode", ("trinary", 0))
    mode = mode_raw.lower()
    if mode not in MODES:
        raise DatasetFormatError(
            f"mode: expected one of {', '.join(MODES)}, got {mode_raw!r}", path, mode_line
        )
    return _Decoding(mode, negate_raw[0].lower() in ("1", "true"), occupied, free)


_TOKEN = re.compile(rb"(?:\s|#[^\n]*(?:\n|$))*([^\s#]+)")


def _header(data: bytes, path: Path) -> tuple[bytes, int, int, int, int]:
    """The PGM header: magic, width, height, maxval and the offset just past maxval."""
    tokens: list[bytes] = []
    pos = 0
    names = ("magic number", "width", "height", "maxval")
    while len(tokens) < 4:
        m = _TOKEN.match(data, pos)
        if m is None:
            raise DatasetFormatError(f"PGM: the header ends before its {names[len(tokens)]}", path)
        tokens.append(m.group(1))
        pos = m.end()
        if tokens[0] not in (b"P5", b"P2"):
            magic = tokens[0][:8]
            hint = " (a PNG: convert it to PGM)" if data.startswith(b"\x89PNG") else ""
            raise DatasetFormatError(
                f"expected a PGM image ('P5' binary or 'P2' text), got {magic!r}{hint}", path
            )
    values = []
    for name, token in zip(names[1:], tokens[1:], strict=True):
        try:
            values.append(int(token))
        except ValueError:
            raise DatasetFormatError(
                f"PGM header: {name} must be an integer, got {token[:20]!r}", path
            ) from None
    cols, rows, maxval = values
    if cols < 1 or rows < 1:
        raise DatasetFormatError(
            f"PGM header: expected at least 1 × 1 pixels, got {cols} × {rows}", path
        )
    if not 0 < maxval <= 255:
        what = "a 16-bit image is not read" if maxval > 255 else "expected 1..255"
        raise DatasetFormatError(f"PGM header: maxval {maxval}: {what}", path)
    return tokens[0], cols, rows, maxval, pos


def read_pgm(path: Path) -> tuple[NDArray[np.uint8], list[str]]:
    """An 8-bit PGM (``P5`` or ``P2``) as ``(rows, cols)`` uint8 scaled to maxval 255, top row
    first, and the notes of what was read past."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DatasetFormatError(f"cannot read the map image ({exc.strerror})", path) from exc
    magic, cols, rows, maxval, pos = _header(data, path)
    notes: list[str] = []
    n = rows * cols
    if magic == b"P5":
        if pos >= len(data) or not data[pos : pos + 1].isspace():
            raise DatasetFormatError("PGM header: expected one whitespace byte after maxval", path)
        pixels = data[pos + 1 :]  # exactly one whitespace byte ends the header
        if len(pixels) < n:
            raise DatasetFormatError(
                f"PGM: expected {n} pixel bytes for {cols} × {rows}, got {len(pixels)} "
                "(a truncated file)",
                path,
            )
        if len(pixels) > n:
            notes.append(f"{path.name}: {len(pixels) - n} bytes after the last pixel ignored")
        values = np.frombuffer(pixels[:n], dtype=np.uint8).astype(np.int64)
    else:
        body = re.sub(rb"#[^\n]*", b" ", data[pos:]).split()
        if len(body) != n:
            raise DatasetFormatError(
                f"PGM (text): expected {n} pixel values for {cols} × {rows}, got {len(body)}",
                path,
            )
        try:
            values = np.array([int(v) for v in body], dtype=np.int64)
        except ValueError:
            raise DatasetFormatError("PGM (text): pixel values must be integers", path) from None
    if values.size and (values.min() < 0 or values.max() > maxval):
        k = int(np.argmax((values < 0) | (values > maxval)))
        raise DatasetFormatError(
            f"PGM: pixel {k} (row {k // cols}, column {k % cols}) is {int(values[k])}, above "
            f"maxval {maxval}",
            path,
        )
    if maxval != 255:
        values = np.round(values * (255.0 / maxval)).astype(np.int64)
    return values.astype(np.uint8).reshape(rows, cols), notes


def decode_pixels(
    img: NDArray[np.uint8],
    mode: str,
    *,
    negate: bool = False,
    occupied_thresh: float = OCCUPIED_THRESHOLD,
    free_thresh: float = FREE_THRESHOLD,
) -> NDArray[np.float64]:
    """Occupancy probabilities of the pixels ``img`` (same shape) under ``map_server``'s
    ``mode`` (module docstring)."""
    v = img.astype(np.float64)
    prob = np.full(v.shape, UNKNOWN)
    if mode == "raw":
        known = v <= 100.0
        prob[known] = v[known] / 100.0
        return prob
    p = v / 255.0 if negate else (255.0 - v) / 255.0
    if mode == "scale":
        prob = 0.99 * (p - free_thresh) / (occupied_thresh - free_thresh)
    prob[p > occupied_thresh] = 1.0
    prob[p < free_thresh] = 0.0
    return prob


def read_ros_map_reading(yaml_path: str | Path) -> RosMapReading:
    """Read a ``map_server`` YAML and its image (module docstring): the grid, its mode and
    the notes of what was read past. Broken input is a
    :class:`~slamkit.errors.DatasetFormatError` naming the file and the line or field."""
    yml = Path(yaml_path)
    fields = _read_yaml(yml)
    notes: list[str] = []
    for key in ("image", "resolution"):
        if key not in fields:
            raise DatasetFormatError(f"missing '{key}'", yml)
    resolution = _number(fields, "resolution", yml, math.nan)
    if not resolution > 0:
        raise DatasetFormatError(
            f"resolution: expected a number > 0, got {resolution}", yml, fields["resolution"][1]
        )
    x0, y0, yaw, origin_line = _origin(fields, yml)
    if yaw != 0.0:
        notes.append(
            f"{yml.name}:{origin_line}: origin yaw {yaw:g} rad ignored: the grid is read "
            "unrotated, placed by the origin's x and y (as ROS's localizers read it)"
        )
    decoding = _decoding(fields, yml)
    unknown = sorted(set(fields) - set(MAP_KEYS), key=lambda k: fields[k][1])
    for key in unknown:
        notes.append(f"{yml.name}:{fields[key][1]}: key '{key}' is not a map_server key: ignored")
    image_raw, image_line = fields["image"]
    image = Path(image_raw)
    image = image if image.is_absolute() else yml.parent / image
    if not image.is_file():
        raise DatasetFormatError(f"image: no such file {str(image)!r}", yml, image_line)
    img, pgm_notes = read_pgm(image)
    notes.extend(pgm_notes)
    prob = decode_pixels(
        img[::-1],  # grid rows run upwards, image rows downwards
        decoding.mode,
        negate=decoding.negate,
        occupied_thresh=decoding.occupied,
        free_thresh=decoding.free,
    )
    grid = OccupancyGrid(np.ascontiguousarray(prob), resolution, np.array([x0, y0]))
    return RosMapReading(grid, decoding.mode, image, tuple(notes))


def read_ros_map(yaml_path: str | Path) -> OccupancyGrid:
    """The grid of :func:`read_ros_map_reading`: 1 (occupied), 0 (free),
    :data:`~slamkit.maps.UNKNOWN` and, in ``scale`` and ``raw`` modes, values in between."""
    return read_ros_map_reading(yaml_path).grid
