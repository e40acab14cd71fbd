"""The fuzz harness of slamkit's readers: small valid inputs, a seeded mutator, a judge.

Each :class:`Target` is one reader with the files of a small valid input it generates (no
real data needed), keyed by their path under a data root. A case mutates one of those files
with one seeded mutation and runs the reader; :func:`judge` sorts the outcome:

* ``typed_line``: a :class:`~slamkit.errors.SlamkitError` whose message names the mutated
  file (or its folder, for a bag) and a line;
* ``typed_no_line``: such an error without a line (a whole-file problem: empty, not gzip);
* ``typed_unnamed``: a slamkit error that does not name the file (a defect);
* ``other``: any other exception, or a NumPy arithmetic warning (a defect);
* ``accepted``: the reader returned, and every float array in its result is finite;
* ``wrong``: the reader returned something with NaN or infinity in it (a defect).

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

OUTCOMES = ("typed_line", "typed_no_line", "typed_unnamed", "other", "accepted", "wrong")
DEFECTS = ("typed_unnamed", "other", "wrong")

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


def semantic_problems(result: Any) -> list[str]:
    """What a finite result may still get wrong: a graph's information matrices must be
    symmetric positive definite (a reader that accepts others has skipped its check)."""
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
    return out


@dataclass
class Outcome:
    kind: str
    mutation: str
    file: str
    detail: str = ""


def judge(run: Callable[[], Any], mutated: Path, mutation: str) -> Outcome:
    """Run a reader on a mutated input and sort what happened (see the module docstring)."""
    rel = mutated.name
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # numpy overflow / invalid value
        try:
            result = run()
        except SlamkitError as exc:
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
    bad = non_finite_paths(result) + semantic_problems(result)
    if bad:
        return Outcome("wrong", mutation, rel, ", ".join(bad[:3]))
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
            if rel in target.binary:
                name, data = mutate_binary(rng, original)
            else:
                name, data = mutate(rng, original, rel.endswith(".gz"))
            path = root / rel
            path.write_bytes(data)
            try:
                yield judge(lambda: target.run(root), path, name)
            finally:
                path.write_bytes(original)


def check_valid(target: Target) -> Any:
    """The reader on the unmutated input (must load: else the fuzzing tests nothing)."""
    with tempfile.TemporaryDirectory() as tmp:
        write_files(Path(tmp), target.files)
        return target.run(Path(tmp))


def remove(path: Path) -> None:
    shutil.rmtree(path, ignore_errors=True)
