"""The fuzz harness of slamkit's readers: small valid inputs, a seeded mutator, a judge.

Each :class:`Target` is one reader with the files of a small valid input it generates (no
real data needed), keyed by their path under a data root. A case mutates one of those files
with one seeded mutation and runs the reader; :func:`judge` sorts the outcome:

* ``typed_line``: a :class:`~slamkit.errors.SlamkitError` whose message names the mutated
  file (or its folder, for a bag) and a line;
* ``typed_no_line``: such an error without a line (a whole-file problem: empty, not gzip);
* ``typed_unnamed``: a slamkit error that does not name the file (a defect);
* ``other``: any other exception, or a NumPy arithmetic warning (a defect);
* ``accepted``: the reader returned a result that is physically plausible
  (:func:`plausibility_problems`): every float array finite, a laser's ranges within
  ``[0, max_range]`` and its beam angles strictly increasing over at most 2π, scan stamps
  strictly increasing, landmark ranges within the sensor's ``max_range``, a graph's
  information symmetric positive definite, and no more dropped than
  :data:`~slamkit.datasets.reading.MAX_DROPPED_SHARE` where the reader says what it read;
* ``wrong``: the reader returned something implausible (a defect);
* ``quirk_refused``: a *quirk* (a real log's oddity: zero, repeated, backward or
  six-digit stamps, a field of view in radians, 181/361 beams, a bag's ``angle_max`` an
  increment off; :data:`QUIRKS`) ended in an error, or was read without the reading
  summary saying what was repaired (a defect: quirks must be read, repaired and counted).

Used by ``test_fuzz_readers.py`` (a few hundred cases per reader) and ``count.py`` (the
long run whose table is in docs/fuzzing.md).
"""

from __future__ import annotations

import dataclasses
import gzip
import math
import re
import shutil
import tempfile
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from slamkit.errors import SlamkitError

OUTCOMES = (
    "typed_line",
    "typed_no_line",
    "typed_unnamed",
    "other",
    "accepted",
    "wrong",
    "quirk_refused",
)
DEFECTS = ("typed_unnamed", "other", "wrong", "quirk_refused")

# ============================================================================ the mutator
NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
BAD_NUMBERS = (
    b"nan",
    b"NaN",
    b"inf",
    b"-inf",
    b"+Infinity",
    b"1e309",
    b"-1e400",
    b"1e300",
    b"-1e300",
    b"1.7e308",
    b"-1.7e308",
    b"9223372036854775808",
    b"-9223372036854775809",
    b"18446744073709551616",
    b"99999999999999999999999",
    b"0",
    b"-0",
    b"-1",
    b"1e-320",
    b"0x10",
    b"1_000",
    b"",
    "\u0661\u0662".encode(),
    "\uff13".encode(),
    "\u00b2".encode(),
    b"1,5",
    b"--1",
    b"1e",
)
SEPARATORS = (
    b"\x0b",
    b"\x0c",
    b"\x1c",
    b"\x1d",
    b"\x1e",
    b"\r",
    "\x85".encode(),
    "\u2028".encode(),
    "\u2029".encode(),
    b"\x00",
    b"\t\t",
    b"\r\n",
)


def _lines(data: bytes) -> list[bytes]:
    return data.split(b"\n")


def _join(lines: list[bytes]) -> bytes:
    return b"\n".join(lines)


def _pick_line(rng: np.random.Generator, lines: list[bytes]) -> int:
    full = [i for i, ln in enumerate(lines) if ln.strip()]
    return int(rng.choice(full)) if full else 0


def m_byte_flip(rng: np.random.Generator, data: bytes) -> bytes:
    if not data:
        return b"\xff"
    b = bytearray(data)
    for _ in range(int(rng.integers(1, 4))):
        b[int(rng.integers(len(b)))] = int(rng.integers(256))
    return bytes(b)


def m_truncate(rng: np.random.Generator, data: bytes) -> bytes:
    return data[: int(rng.integers(len(data) + 1))]


def m_delete_line(rng: np.random.Generator, data: bytes) -> bytes:
    lines = _lines(data)
    del lines[_pick_line(rng, lines)]
    return _join(lines)


def m_duplicate_line(rng: np.random.Generator, data: bytes) -> bytes:
    lines = _lines(data)
    i = _pick_line(rng, lines)
    lines.insert(i, lines[i])
    return _join(lines)


def m_swap_lines(rng: np.random.Generator, data: bytes) -> bytes:
    lines = _lines(data)
    i, j = _pick_line(rng, lines), _pick_line(rng, lines)
    lines[i], lines[j] = lines[j], lines[i]
    return _join(lines)


def _fields_edit(rng: np.random.Generator, data: bytes, how: str) -> bytes:
    lines = _lines(data)
    i = _pick_line(rng, lines)
    fields = lines[i].split()
    if not fields:
        return data
    k = int(rng.integers(len(fields)))
    if how == "delete":
        del fields[k]
    else:
        fields.insert(k, fields[k])
    lines[i] = b" ".join(fields)
    return _join(lines)


def m_delete_field(rng: np.random.Generator, data: bytes) -> bytes:
    return _fields_edit(rng, data, "delete")


def m_duplicate_field(rng: np.random.Generator, data: bytes) -> bytes:
    return _fields_edit(rng, data, "duplicate")


def _numbers(data: bytes) -> list[re.Match[bytes]]:
    return list(NUMBER.finditer(data))


def m_bad_number(rng: np.random.Generator, data: bytes) -> bytes:
    nums = _numbers(data)
    if not nums:
        return data + b" nan"
    m = nums[int(rng.integers(len(nums)))]
    new = BAD_NUMBERS[int(rng.integers(len(BAD_NUMBERS)))]
    return data[: m.start()] + new + data[m.end() :]


def m_scale_number(rng: np.random.Generator, data: bytes) -> bytes:
    """A number negated or scaled far out (non-PD information, huge ranges, time jumps)."""
    nums = _numbers(data)
    if not nums:
        return data
    m = nums[int(rng.integers(len(nums)))]
    try:
        v = float(m.group())
    except ValueError:
        return data
    factor = float(rng.choice([-1.0, -1e3, 1e12, 1e200, 1e-200, 0.0]))
    return data[: m.start()] + repr(v * factor if v else factor).encode() + data[m.end() :]


def m_separator(rng: np.random.Generator, data: bytes) -> bytes:
    pos = int(rng.integers(len(data) + 1))
    sep = SEPARATORS[int(rng.integers(len(SEPARATORS)))]
    return data[:pos] + sep + data[pos:]


def m_garbage(rng: np.random.Generator, data: bytes) -> bytes:
    pos = int(rng.integers(len(data) + 1))
    junk = rng.integers(0, 256, size=int(rng.integers(1, 64))).astype(np.uint8).tobytes()
    return data[:pos] + junk + data[pos:]


def m_empty(rng: np.random.Generator, data: bytes) -> bytes:
    return [b"", b"\n", b"   \n\n", b"# only a comment\n"][int(rng.integers(4))]


def m_header_only(rng: np.random.Generator, data: bytes) -> bytes:
    lines = [ln for ln in _lines(data) if ln.lstrip().startswith((b"#", b"PARAM"))]
    return _join(lines[: int(rng.integers(len(lines) + 1))]) + b"\n"


TEXT_MUTATIONS: dict[str, Callable[[np.random.Generator, bytes], bytes]] = {
    "byte_flip": m_byte_flip,
    "truncate": m_truncate,
    "delete_line": m_delete_line,
    "duplicate_line": m_duplicate_line,
    "swap_lines": m_swap_lines,
    "delete_field": m_delete_field,
    "duplicate_field": m_duplicate_field,
    "bad_number": m_bad_number,
    "bad_number_2": m_bad_number,  # weighted: numbers are where most readers differ
    "scale_number": m_scale_number,
    "separator": m_separator,
    "garbage": m_garbage,
    "empty": m_empty,
    "header_only": m_header_only,
}


def mutate(rng: np.random.Generator, data: bytes, gz: bool) -> tuple[str, bytes]:
    """One seeded mutation of a file's bytes: ``(name, new bytes)``. For a gzip file the text
    inside is mutated and compressed again, or (1 in 8) the compressed body is damaged."""
    if gz and rng.random() < 0.125:
        body = bytearray(data)
        kind = int(rng.integers(3))
        if kind == 0:  # a flipped byte inside the deflate stream
            i = int(rng.integers(10, max(11, len(body) - 8)))
            body[i] ^= 1 + int(rng.integers(255))
            return "bad_gzip_body", bytes(body)
        if kind == 1:  # cut short
            return "bad_gzip_truncated", bytes(body[: int(rng.integers(len(body)))])
        return "bad_gzip_plain", gzip.decompress(data)  # plain text in a .gz name
    names = list(TEXT_MUTATIONS)
    name = names[int(rng.integers(len(names)))]
    text = gzip.decompress(data) if gz else data
    new = TEXT_MUTATIONS[name](rng, text)
    return name, gzip.compress(new, mtime=0) if gz else new


def mutate_binary(rng: np.random.Generator, data: bytes) -> tuple[str, bytes]:
    """Mutations of a binary file (a ROS bag): flips, cuts, garbage, zeroed spans."""
    kind = int(rng.integers(5))
    if kind == 0:
        return "byte_flip", m_byte_flip(rng, data)
    if kind == 1:
        return "truncate", m_truncate(rng, data)
    if kind == 2:
        return "garbage", m_garbage(rng, data)
    if kind == 3:
        b = bytearray(data)
        i = int(rng.integers(len(b)))
        n = int(rng.integers(1, 32))
        b[i : i + n] = bytes(len(b[i : i + n]))
        return "zero_span", bytes(b)
    # a float32 / float64 inside set to NaN or a huge value (aligned at random)
    b = bytearray(data)
    i = int(rng.integers(len(b) - 8))
    val = float(rng.choice([math.nan, math.inf, -math.inf, 1e38, -3e38]))
    if rng.random() < 0.5:
        b[i : i + 4] = np.float32(val).tobytes()
    else:
        b[i : i + 8] = np.float64(val).tobytes()
    return "bad_float", bytes(b)


# ============================================================================ the quirks
# Real logs are quirky rather than broken. A quirk mutation makes a valid log look like one
# of the field's; the reader must read it, repair it and say so (never refuse it).
LASER_TAGS = (b"FLASER", b"RLASER", b"ROBOTLASER1", b"RAWLASER1", b"RAWLASER2", b"RAWLASER3")
STAMPED_TAGS = (*LASER_TAGS, b"ODOM")


def _stamp_slots(fields: list[bytes]) -> tuple[int, ...]:
    """Where the stamps of a CARMEN line are: ``ts host logger_ts`` at the end (or ``ts``)."""
    if len(fields) >= 3 and NUMBER.fullmatch(fields[-3]) and not NUMBER.fullmatch(fields[-2]):
        return (len(fields) - 3, len(fields) - 1)
    return (len(fields) - 1,)


def _rewrite_stamps(
    data: bytes, tags: tuple[bytes, ...], edit: Callable[[int, float, float | None], float | None]
) -> bytes:
    """Apply ``edit(k, stamp, previous stamp) -> new stamp or None`` to the ``k``-th line of
    ``tags`` (both of its stamp fields)."""
    lines = _lines(data)
    k, previous = 0, None
    for i, line in enumerate(lines):
        fields = line.split()
        if not fields or fields[0] not in tags:
            continue
        slots = _stamp_slots(fields)
        try:
            t = float(fields[slots[0]])
        except ValueError:
            continue
        new = edit(k, t, previous)
        if new is not None:
            for j in slots:
                fields[j] = repr(new).encode() if not isinstance(new, str) else new.encode()
            lines[i] = b" ".join(fields)
        previous = t if new is None else (float(new) if not isinstance(new, str) else t)
        k += 1
    return _join(lines)


def _laser_count(data: bytes) -> int:
    return sum(1 for ln in _lines(data) if ln.split()[:1] and ln.split()[0] in LASER_TAGS)


def _some(rng: np.random.Generator, data: bytes, how_many: int) -> set[int]:
    """A few laser lines (not the first, whose stamp anchors the log), at random."""
    n = _laser_count(data)
    return {int(k) for k in rng.choice(np.arange(1, n), size=min(how_many, n - 1), replace=False)}


def q_zero_stamps(rng: np.random.Generator, data: bytes) -> bytes:
    picked = _some(rng, data, int(rng.integers(1, 3)))
    return _rewrite_stamps(data, LASER_TAGS, lambda k, t, _: 0.0 if k in picked else None)


def q_repeated_stamps(rng: np.random.Generator, data: bytes) -> bytes:
    picked = _some(rng, data, 1)
    return _rewrite_stamps(data, LASER_TAGS, lambda k, t, prev: prev if k in picked else None)


def q_stamp_back(rng: np.random.Generator, data: bytes) -> bytes:
    picked = _some(rng, data, 1)
    return _rewrite_stamps(
        data, LASER_TAGS, lambda k, t, prev: (prev or t) - 1.0 if k in picked else None
    )


def q_low_precision(rng: np.random.Generator, data: bytes) -> bytes:
    """Every stamp (laser and ODOM lines) printed with six significant digits."""

    def edit(k: int, t: float, prev: float | None) -> Any:
        return f"{t:.6g}"

    return _rewrite_stamps(data, STAMPED_TAGS, edit)


def q_fov_radians(rng: np.random.Generator, data: bytes) -> bytes:
    """The field of view (and the resolution, when stated) written in radians."""
    lines = _lines(data)
    found = False
    for i, line in enumerate(lines):
        f = line.split()
        if len(f) >= 3 and f[0] == b"PARAM" and f[1].endswith((b"laser_fov", b"_resolution")):
            f[2] = f"{math.radians(float(f[2])):.6g}".encode()
            found = found or f[1].endswith(b"laser_fov")
            lines[i] = b" ".join(f)
    if not found:
        lines.insert(0, b"PARAM laser_front_laser_fov 3.14159")
    return _join(lines)


def _beams(n_new: int) -> Callable[[np.random.Generator, bytes], bytes]:
    def mutation(rng: np.random.Generator, data: bytes) -> bytes:
        """Every FLASER line resampled to ``n_new`` beams; no geometry stated (the count
        is the geometry, 180°)."""
        out = []
        for line in _lines(data):
            f = line.split()
            if f[:1] == [b"PARAM"] and f[1].endswith((b"laser_fov", b"_resolution")):
                continue
            if f[:1] == [b"FLASER"]:
                n = int(f[1])
                old = np.asarray([float(v) for v in f[2 : 2 + n]])
                new = np.interp(np.linspace(0, n - 1, n_new), np.arange(n), old)
                f = [b"FLASER", str(n_new).encode(), *(f"{v:.3f}".encode() for v in new),
                     *f[2 + n :]]  # fmt: skip
            out.append(b" ".join(f))
        return _join(out)

    return mutation


QUIRKS: dict[str, Callable[[np.random.Generator, bytes], bytes]] = {
    "quirk_zero_stamps": q_zero_stamps,
    "quirk_repeated_stamps": q_repeated_stamps,
    "quirk_stamp_back": q_stamp_back,
    "quirk_low_precision_stamps": q_low_precision,
    "quirk_fov_radians": q_fov_radians,
    "quirk_181_beams": _beams(181),
    "quirk_361_beams": _beams(361),
}
"""The quirks of CARMEN logs (text): name -> mutation. A target lists those that apply."""
QUIRK_SHARE = 0.2
"""The share of a quirky target's cases that are quirks."""
BEAM_QUIRKS = ("quirk_181_beams", "quirk_361_beams")
"""Quirks that need no repair: the beam count is the geometry (180°), and is checked."""


# ============================================================================ the judge
def non_finite_paths(obj: Any, where: str = "result", seen: set[int] | None = None) -> list[str]:
    """Where ``obj`` (dataclasses, mappings, sequences, arrays, floats) holds NaN or inf."""
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return []
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind in "fc" and not np.all(np.isfinite(obj)):
            return [where]
        if obj.dtype.kind in "iu" and obj.size and np.max(np.abs(obj.astype(np.float64))) > 2**53:
            return [where + " (an integer beyond 2^53: wrapped or huge)"]
        if obj.dtype == object:
            return [p for i, v in enumerate(obj.flat) for p in non_finite_paths(v, where, seen)]
        return []
    if isinstance(obj, float | np.floating):
        if where.endswith("max_range") and float(obj) == math.inf:
            return []  # documented: a sensor without a range limit
        return [] if math.isfinite(float(obj)) else [where]
    if isinstance(obj, str | bytes | int | bool | Path) or obj is None:
        return []
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out: list[str] = []
        for f in dataclasses.fields(obj):
            out += non_finite_paths(getattr(obj, f.name, None), f"{where}.{f.name}", seen)
        return out
    if isinstance(obj, dict) or hasattr(obj, "items"):
        try:
            items = list(obj.items())
        except Exception:
            return []
        return [p for k, v in items for p in non_finite_paths(v, f"{where}[{k!r}]", seen)]
    if isinstance(obj, list | tuple):
        out = []
        for i, v in enumerate(obj):
            out += non_finite_paths(v, f"{where}[{i}]", seen)
            if len(out) > 3:
                break
        return out
    return []


def plausibility_problems(result: Any) -> list[str]:
    """What a finite result may still get wrong, physically (see the module docstring)."""
    from slamkit.datasets.stream import Dataset
    from slamkit.optim.data import GraphData

    out: list[str] = []
    if isinstance(result, GraphData):
        for e in result.edges:
            info = e.information
            if info.size == 0:
                continue
            if not np.allclose(info, np.swapaxes(info, 1, 2), rtol=1e-9, atol=0.0):
                out.append(f"{e.kind}: information not symmetric")
            elif np.min(np.linalg.eigvalsh(info)) <= 0:
                out.append(f"{e.kind}: information not positive definite")
    if isinstance(result, Dataset):
        out += _laser_problems(result) + _landmark_problems(result) + _dropped_problems(result)
    return out


def _laser_problems(ds: Any) -> list[str]:
    from slamkit.datasets.stream import LaserScan

    out: list[str] = []
    if ds.laser is None:
        return out
    angles = ds.laser.beam_angles
    if angles.size > 1 and not np.all(np.diff(angles) > 0):
        out.append("laser.beam_angles: not strictly increasing")
    if angles.size and angles[-1] - angles[0] > 2.0 * math.pi + 1e-6:
        out.append(f"laser.beam_angles: span {angles[-1] - angles[0]!r} rad, over 2π")
    scans = [ev for ev in ds.events if isinstance(ev, LaserScan)]
    if scans:
        ranges = np.stack([ev.ranges for ev in scans])
        if np.any(ranges < 0) or np.any(ranges > ds.laser.max_range):
            out.append(f"scan ranges outside [0, max_range {ds.laser.max_range!r}]")
        t = np.asarray([ev.t for ev in scans])
        if np.any(np.diff(t) <= 0):
            out.append("scan stamps not strictly increasing")
    return out


def _landmark_problems(ds: Any) -> list[str]:
    from slamkit.datasets.stream import LandmarkReadings

    sensor = ds.landmark_sensor
    if sensor is None or sensor.kind not in ("range-bearing", "range-only"):
        return []
    z = [ev.z for ev in ds.events if isinstance(ev, LandmarkReadings) and ev.z.size]
    if not z:
        return []
    r = np.concatenate(z)[:, 0]
    if np.any(r < 0) or np.any(r > sensor.max_range):
        return [f"landmark ranges outside [0, max_range {sensor.max_range!r}]: {r.max()!r}"]
    return []


def _dropped_problems(ds: Any) -> list[str]:
    from slamkit.datasets.reading import FEW_DROPPED, MAX_DROPPED_SHARE

    r = ds.reading
    if r is None or r.used >= r.records - max(FEW_DROPPED, MAX_DROPPED_SHARE * r.records):
        return []
    return [f"reading: {r.used} of {r.records} {r.what} used, more dropped than allowed"]


def _quirk_problems(result: Any, mutation: str) -> list[str]:
    """A quirk must come out repaired and counted: the reading summary says something was
    done (the beam-count quirks need no repair: their scans span 180°)."""
    from slamkit.datasets.stream import Dataset

    if not isinstance(result, Dataset):
        return ["not a data set"]
    if mutation in BEAM_QUIRKS:
        assert result.laser is not None
        a = result.laser.beam_angles
        return [] if abs(a[-1] - a[0] - math.pi) < 1e-9 else [f"span {a[-1] - a[0]!r} rad"]
    if result.reading is None or result.reading.clean:
        return ["read, but the reading summary reports no repair"]
    return []


@dataclass
class Outcome:
    kind: str
    mutation: str
    file: str
    detail: str = ""


def judge(
    run: Callable[[], Any],
    mutated: Path,
    mutation: str,
    check: Callable[[Any], list[str]] | None = None,
    quirk: bool = False,
) -> Outcome:
    """Run a reader on a mutated input and sort what happened (see the module docstring).
    ``check`` adds the target's own plausibility checks; ``quirk``: the mutation is one of
    the quirks, which must be read and repaired."""
    rel = mutated.name
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # numpy overflow / invalid value
        try:
            result = run()
        except SlamkitError as exc:
            if quirk:
                return Outcome("quirk_refused", mutation, rel, f"{type(exc).__name__}: {exc}")
            msg = str(exc)
            named = str(mutated) in msg or mutated.name in msg
            if not named:
                return Outcome("typed_unnamed", mutation, rel, f"{type(exc).__name__}: {msg}")
            has_line = getattr(exc, "line", None) is not None or bool(
                re.search(re.escape(mutated.name) + r":\d+", msg)
            )
            kind = "typed_line" if has_line else "typed_no_line"
            return Outcome(kind, mutation, rel, f"{type(exc).__name__}: {msg[:200]}")
        except Exception as exc:
            return Outcome("other", mutation, rel, f"{type(exc).__name__}: {exc}"[:300])
    bad = non_finite_paths(result) + plausibility_problems(result)
    bad += check(result) if check is not None else []
    if bad:
        return Outcome("wrong", mutation, rel, ", ".join(bad[:3]))
    if quirk and (why := _quirk_problems(result, mutation)):
        return Outcome("quirk_refused", mutation, rel, ", ".join(why))
    return Outcome("accepted", mutation, rel)


# ============================================================================ the targets
@dataclass(frozen=True)
class Target:
    """One reader: its valid input files (path under the root -> bytes) and how to run it."""

    name: str
    files: dict[str, bytes]
    run: Callable[[Path], Any]
    binary: tuple[str, ...] = ()
    mutable: tuple[str, ...] = field(default=())
    check: Callable[[Any], list[str]] | None = None
    """The target's own plausibility checks of a result (problems; empty: plausible)."""
    quirks: dict[str, Callable[[np.random.Generator, bytes], bytes]] = field(default_factory=dict)
    """The quirk mutations that apply to this reader's files (name -> mutation of the
    uncompressed bytes), drawn in :data:`QUIRK_SHARE` of the cases."""

    def targets(self) -> tuple[str, ...]:
        return self.mutable or tuple(self.files)


def write_files(root: Path, files: dict[str, bytes]) -> None:
    for rel, data in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)


def cases(target: Target, n: int, seed: int) -> Iterator[Outcome]:
    """``n`` seeded mutations of ``target``'s input, each judged; one temporary root."""
    rng = np.random.default_rng([seed, sum(map(ord, target.name))])
    with tempfile.TemporaryDirectory(prefix=f"fuzz-{target.name}-") as tmp:
        root = Path(tmp)
        write_files(root, target.files)
        for _ in range(n):
            rels = target.targets()
            rel = rels[int(rng.integers(len(rels)))]
            original = target.files[rel]
            quirk = bool(target.quirks) and rng.random() < QUIRK_SHARE
            if quirk:
                names = sorted(target.quirks)
                name = names[int(rng.integers(len(names)))]
                gz = rel.endswith(".gz")
                text = gzip.decompress(original) if gz else original
                data = target.quirks[name](rng, text)
                data = gzip.compress(data, mtime=0) if gz else data
            elif rel in target.binary:
                name, data = mutate_binary(rng, original)
            else:
                name, data = mutate(rng, original, rel.endswith(".gz"))
            path = root / rel
            path.write_bytes(data)
            try:
                yield judge(lambda: target.run(root), path, name, target.check, quirk)
            finally:
                path.write_bytes(original)


def check_valid(target: Target) -> Any:
    """The reader on the unmutated input (must load: else the fuzzing tests nothing)."""
    with tempfile.TemporaryDirectory() as tmp:
        write_files(Path(tmp), target.files)
        return target.run(Path(tmp))


def remove(path: Path) -> None:
    shutil.rmtree(path, ignore_errors=True)
