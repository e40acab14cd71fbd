"""The record structure of a ROS 1 bag, checked before ``rosbags`` reads it.

A ROS 1 bag (format 2.0) is the line ``#ROSBAG V2.0`` followed by records, each
``header_len (uint32) header data_len (uint32) data``, the header a list of
``field_len (uint32) name=value`` fields with the record's ``op``. ``rosbags`` trusts every
length it reads: a length damaged to 4 GiB makes it ask for a 4 GiB buffer (Python's file
``read(n)`` allocates ``n`` bytes before it reads), for a bag of 25 kB. And it seeks to the
offsets the bag states (``index_pos`` in the bag header, ``chunk_pos`` in every chunk info
record): an offset into the middle of a record makes it read lengths out of message data.

:func:`check_bag1_records` walks the records from the start, reading only their headers, and
refuses (with :class:`~slamkit.errors.DatasetFormatError` naming the file and the byte
offset) a record that would end beyond the file and an offset that is not the start of a
record of the right kind. Past that check every length ``rosbags`` reads at the top level is
bounded by the file's size (inside a chunk it reads from memory, where a read is bounded by
what is there).
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import BinaryIO

from slamkit.errors import DatasetFormatError

__all__ = ["BAG1_MAGIC", "MCAP_MAGIC", "check_bag1_records", "check_mcap_records"]

BAG1_MAGIC = b"#ROSBAG V2.0\n"
"""The first line of a ROS 1 bag of the format read here."""

MCAP_MAGIC = b"\x89MCAP0\r\n"
"""The first (and last) eight bytes of an MCAP file."""
MCAP_CHUNK = 0x06
MCAP_FOOTER = 0x02
MCAP_MAX_INFLATION = 1024
"""A compressed chunk may state at most this many times its size, uncompressed: zstd and
lz4 reach a few hundred on runs of zeros; more is a damaged length, not a real chunk."""

OP_BAG_HEADER = 0x03
OP_CHUNK = 0x05
OP_CHUNK_INFO = 0x06


def _fields(header: bytes) -> dict[bytes, bytes] | None:
    """The ``name=value`` fields of a record header; None when a field length overruns it."""
    out: dict[bytes, bytes] = {}
    pos = 0
    while pos < len(header):
        if pos + 4 > len(header):
            return None
        (size,) = struct.unpack_from("<I", header, pos)
        pos += 4
        if pos + size > len(header):
            return None
        name, _, value = header[pos : pos + size].partition(b"=")
        out[name] = value
        pos += size
    return out


def _offset(fields: dict[bytes, bytes], name: bytes) -> int | None:
    value = fields.get(name)
    return None if value is None or len(value) != 8 else int(struct.unpack("<Q", value)[0])


def _walk(src: BinaryIO, size: int, path: Path) -> dict[int, int]:
    """Every top-level record's offset → op; refuses a record that ends beyond the file."""
    ops: dict[int, int] = {}
    pos = len(BAG1_MAGIC)
    while pos < size:
        src.seek(pos)
        head = src.read(4)
        header_len = struct.unpack("<I", head)[0] if len(head) == 4 else size
        if pos + 8 + header_len > size:
            raise DatasetFormatError(
                f"cannot read the bag: the record at byte {pos} has a header of {header_len} "
                f"bytes, beyond the file's {size} bytes (a damaged or cut bag)",
                path,
            )
        fields = _fields(src.read(header_len))
        (data_len,) = struct.unpack("<I", src.read(4))
        op = None if fields is None else fields.get(b"op")
        if op is None or len(op) != 1 or pos + 8 + header_len + data_len > size:
            raise DatasetFormatError(
                f"cannot read the bag: the record at byte {pos} ({header_len} + {data_len} "
                f"bytes) is damaged or ends beyond the file's {size} bytes",
                path,
            )
        ops[pos] = op[0]
        pos += 8 + header_len + data_len
    return ops


def check_bag1_records(path: Path) -> None:
    """Refuse a ROS 1 bag whose records overrun the file or whose stated offsets
    (``index_pos``, ``chunk_pos``) are not the start of a record of the right kind (see the
    module docstring). A file that does not start with :data:`BAG1_MAGIC` is left to
    ``rosbags``."""
    size = path.stat().st_size
    with path.open("rb") as src:
        if src.read(len(BAG1_MAGIC)) != BAG1_MAGIC:
            return
        ops = _walk(src, size, path)
        for pos, op in list(ops.items()):
            if op not in (OP_BAG_HEADER, OP_CHUNK_INFO):
                continue
            src.seek(pos)
            (header_len,) = struct.unpack("<I", src.read(4))
            fields = _fields(src.read(header_len)) or {}
            name, want = (b"index_pos", None) if op == OP_BAG_HEADER else (b"chunk_pos", OP_CHUNK)
            target = _offset(fields, name)
            if op == OP_BAG_HEADER and target in (0, size):
                continue  # not indexed (rosbags says so), or an empty index
            if target is None or target not in ops or (want is not None and ops[target] != want):
                raise DatasetFormatError(
                    f"cannot read the bag: the {name.decode()} {target} stated at byte {pos} "
                    "is not the start of a record of the bag (a damaged bag)",
                    path,
                )


def check_mcap_records(path: Path) -> None:
    """Refuse an MCAP file whose top-level records (``opcode (uint8) length (uint64)
    content``) would end beyond the file, or whose chunk states an uncompressed size that
    its records cannot hold (the readers allocate what a length says before they read, as
    for ROS 1 above). A file that does not start with :data:`MCAP_MAGIC` is left to
    ``rosbags``."""
    size = path.stat().st_size
    with path.open("rb") as src:
        if src.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            return
        pos = len(MCAP_MAGIC)
        while pos + 9 <= size:
            src.seek(pos)
            op, length = struct.unpack("<BQ", src.read(9))
            if pos + 9 + length > size:
                raise DatasetFormatError(
                    f"cannot read the MCAP file: the record at byte {pos} ({length} bytes) "
                    f"ends beyond the file's {size} bytes (a damaged or cut file)",
                    path,
                )
            if op == MCAP_CHUNK:
                _check_mcap_chunk(src.read(min(length, 64)), length, pos, path)
            if op == MCAP_FOOTER:
                return
            pos += 9 + length


def _check_mcap_chunk(head: bytes, length: int, pos: int, path: Path) -> None:
    """A chunk's ``uncompressed_size`` against what its records can hold: equal to them
    uncompressed, at most :data:`MCAP_MAX_INFLATION` times them compressed."""
    if len(head) < 32:
        raise DatasetFormatError(f"cannot read the MCAP file: the chunk at byte {pos} is cut", path)
    uncompressed = struct.unpack_from("<Q", head, 16)[0]
    (name_len,) = struct.unpack_from("<I", head, 28)
    records = length - 32 - name_len - 8  # what is left for the records, at most
    if records < 0 or uncompressed > MCAP_MAX_INFLATION * max(records, 1):
        raise DatasetFormatError(
            f"cannot read the MCAP file: the chunk at byte {pos} states {uncompressed} "
            f"bytes uncompressed in {length} bytes (a damaged length)",
            path,
        )
