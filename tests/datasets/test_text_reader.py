"""The shared numeric text-table reader: strict errors name file and line; lenient mode
skips and counts; gzip by suffix; values round-trip exactly."""

from __future__ import annotations

import gzip
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from slamkit.datasets.text import MAX_REPORTED_LINES, read_table
from slamkit.errors import DataNotFoundError, DatasetFormatError

GOOD = """# a header line
# time v omega
1.0\t0.5\t-0.25
  2.0 0.5   0.0\t

3.5 1e-3 -2E+1   # trailing comment
"""


def _write(path: Path, text: str) -> Path:
    if path.suffix == ".gz":
        with gzip.open(path, "wt", encoding="utf-8") as fh:
            fh.write(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize("name", ["table.dat", "table.dat.gz"])
def test_reads_whitespace_table_with_comments(tmp_path: Path, name: str) -> None:
    table = read_table(_write(tmp_path / name, GOOD), 3)
    np.testing.assert_array_equal(
        table.values, [[1.0, 0.5, -0.25], [2.0, 0.5, 0.0], [3.5, 1e-3, -20.0]]
    )
    np.testing.assert_array_equal(table.line_numbers, [3, 4, 6])
    assert table.skipped == 0 and table.skipped_lines == ()
    assert table.values.dtype == np.float64 and table.values.flags.c_contiguous
    assert len(table) == 3


def test_reads_comma_separated(tmp_path: Path) -> None:
    path = _write(tmp_path / "t.csv", "# id,x,y\n0, -46.6, 11.0\n1,11.0,-6.9\n")
    table = read_table(path, 3, delimiter=",")
    np.testing.assert_array_equal(table.values, [[0, -46.6, 11.0], [1, 11.0, -6.9]])
    with pytest.raises(DatasetFormatError) as err:
        read_table(_write(tmp_path / "e.csv", "1,,2\n"), 3, delimiter=",")
    assert err.value.line == 1 and "column 2" in str(err.value)


@pytest.mark.parametrize("suffix", ["", ".gz"])
@pytest.mark.parametrize(
    "bad_line,expected",
    [
        ("4.0 1.0", "expected 3 columns, got 2"),
        ("4.0 1.0 2.0 3.0", "expected 3 columns, got 4"),
        ("4.0 fast 2.0", "column 2: expected a number, got 'fast'"),
        ("4.0 1.0 nan", "column 3: expected a finite number, got 'nan'"),
        ("-inf 1.0 2.0", "column 1: expected a finite number, got '-inf'"),
        ("4.0 1e400 2.0", "column 2: expected a finite number, got '1e400'"),
    ],
)
def test_strict_error_names_file_and_line(
    tmp_path: Path, suffix: str, bad_line: str, expected: str
) -> None:
    lines = GOOD.splitlines()
    lines.insert(4, bad_line)  # becomes physical line 5
    lines.append("7.0 8.0 also-bad")  # a later bad line must not be the one reported
    path = _write(tmp_path / f"odometry.dat{suffix}", "\n".join(lines) + "\n")
    with pytest.raises(DatasetFormatError) as err:
        read_table(path, 3)
    assert err.value.path == path
    assert err.value.line == 5
    assert expected in str(err.value)
    assert str(err.value).startswith(f"{path}:5: ")


def test_strict_reports_the_first_bad_line_of_any_kind(tmp_path: Path) -> None:
    text = "1 2 3\n1 two 3\n4 5 6\n7 8\n"
    with pytest.raises(DatasetFormatError, match="column 2") as err:
        read_table(_write(tmp_path / "a.txt", text), 3)
    assert err.value.line == 2
    text = "1 2 3\n1 2\n4 5 inf\n"
    with pytest.raises(DatasetFormatError, match="expected 3 columns, got 2") as err:
        read_table(_write(tmp_path / "b.txt", text), 3)
    assert err.value.line == 2


def test_lenient_skips_and_counts(tmp_path: Path) -> None:
    text = "1 2 3\n1 2\nx 2 3\n4 5 6\n7 8 nan\n# c\n9 10 11 12\n13 14 15\n"
    table = read_table(_write(tmp_path / "m.txt", text), 3, lenient=True)
    np.testing.assert_array_equal(table.values, [[1, 2, 3], [4, 5, 6], [13, 14, 15]])
    np.testing.assert_array_equal(table.line_numbers, [1, 4, 8])
    assert table.skipped == 4
    assert table.skipped_lines == (2, 3, 5, 7)


def test_lenient_reports_a_bounded_number_of_lines(tmp_path: Path) -> None:
    text = "".join("1 2\n" if i % 2 else "1 2 3\n" for i in range(100))
    table = read_table(_write(tmp_path / "m.txt", text), 3, lenient=True)
    assert table.skipped == 50 and len(table) == 50
    assert table.skipped_lines == tuple(range(2, 2 * MAX_REPORTED_LINES + 1, 2))


def test_an_empty_file_is_refused_unless_allowed(tmp_path: Path) -> None:
    """The same rule for every reader: a file of headers only is not data."""
    path = _write(tmp_path / "e.txt", "# only a header\n\n")
    with pytest.raises(DatasetFormatError, match=r"e\.txt: expected at least 1 data row"):
        read_table(path, 4)
    with pytest.raises(DatasetFormatError, match="2 malformed line"):
        read_table(_write(tmp_path / "f.txt", "1 2\n3\n"), 4, lenient=True)
    table = read_table(path, 4, min_rows=0)
    assert table.values.shape == (0, 4) and table.line_numbers.shape == (0,)


def test_missing_and_corrupt_files(tmp_path: Path) -> None:
    with pytest.raises(DataNotFoundError, match="not found"):
        read_table(tmp_path / "absent.txt", 3)
    corrupt = tmp_path / "broken.txt.gz"
    corrupt.write_bytes(b"this is not gzip data")
    with pytest.raises(DatasetFormatError, match="gzip") as err:
        read_table(corrupt, 3)
    assert err.value.path == corrupt
    binary = tmp_path / "binary.txt"
    binary.write_bytes(b"1 2 3\n\xff\xfe 4\n")
    with pytest.raises(DatasetFormatError, match="UTF-8"):
        read_table(binary, 3)
    with pytest.raises(ValueError, match="columns"):
        read_table(binary, 0)


@settings(max_examples=40, deadline=None)
@given(
    arrays(
        np.float64,
        st.tuples(st.integers(0, 30), st.integers(1, 6)),
        elements=st.floats(allow_nan=False, allow_infinity=False, width=64),
    )
)
def test_values_round_trip_exactly(tmp_path_factory: pytest.TempPathFactory, data) -> None:
    path = tmp_path_factory.mktemp("rt") / "table.txt"
    # repr() of a float is the shortest string that reads back to the same float.
    text = "# header\n" + "".join("\t".join(repr(float(v)) for v in row) + "\n" for row in data)
    path.write_text(text, encoding="utf-8")
    table = read_table(path, data.shape[1], min_rows=0)
    np.testing.assert_array_equal(table.values, data.reshape(-1, data.shape[1]))


def test_large_gzip_file_reads_fast(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    rows = np.column_stack([np.arange(100_000) * 0.01 + 1.2e9, rng.normal(size=(100_000, 2))])
    text = "# time v omega\n" + "".join(f"{t:.3f}\t{v:.3f}\t{w:.3f}\n" for t, v, w in rows)
    path = _write(tmp_path / "big.dat.gz", text)
    tic = time.perf_counter()
    table = read_table(path, 3)
    elapsed = time.perf_counter() - tic
    assert table.values.shape == (100_000, 3)
    np.testing.assert_allclose(table.values, np.round(rows, 3), rtol=0, atol=1e-6)
    assert elapsed < 2.0  # typically ~0.15 s


def test_line_numbers_count_newlines_only(tmp_path):
    text = "1 2\n# \x0b \x0c \x1c \x85 \u2028 \u2029 in a comment\n3 x\n"
    with pytest.raises(DatasetFormatError, match=r"t\.txt:3:"):
        read_table(_write(tmp_path / "t.txt", text), 2)


def test_numbers_are_ascii_only(tmp_path):
    with pytest.raises(DatasetFormatError, match=r"t\.txt:2: .*non-ASCII"):
        read_table(_write(tmp_path / "t.txt", "1 2\n١٢ 3\n"), 2)
    table = read_table(_write(tmp_path / "u.txt", "1 2  # Tübingen\n"), 2)  # comments may
    np.testing.assert_array_equal(table.values, [[1.0, 2.0]])


def test_a_corrupt_gzip_body_and_bad_utf8_are_format_errors(tmp_path):
    good = gzip.compress(GOOD.encode())
    bad = bytearray(good)
    bad[len(bad) // 2] ^= 0xFF
    (tmp_path / "c.txt.gz").write_bytes(bytes(bad))
    with pytest.raises(DatasetFormatError, match=r"c\.txt\.gz"):
        read_table(tmp_path / "c.txt.gz", 3)
    (tmp_path / "b.txt").write_bytes(b"1 2 3\n4 5 \xff\n")
    with pytest.raises(DatasetFormatError, match=r"b\.txt:2: not UTF-8"):
        read_table(tmp_path / "b.txt", 3)


def test_integer_fields_have_bounds(tmp_path):
    """Ids of 2^63 or more were cast to -9223372036854775808 by NumPy; beyond 2^53 a float
    table cannot hold them exactly: refused with the line."""
    from slamkit.datasets.text import integer_column

    path = _write(tmp_path / "ids.txt", "1 0.5\n9223372036854775808 0.5\n")
    table = read_table(path, 2)
    with pytest.raises(DatasetFormatError, match=r"ids\.txt:2: expected an integer id"):
        integer_column(table, 0, "id", path)
    ok = read_table(_write(tmp_path / "ok.txt", "3 0.5\n-7 1\n"), 2)
    np.testing.assert_array_equal(integer_column(ok, 0, "id", path), [3, -7])
    with pytest.raises(DatasetFormatError, match=r":1: expected an integer id"):
        integer_column(read_table(_write(tmp_path / "f.txt", "1.5 2\n"), 2), 0, "id", path)
