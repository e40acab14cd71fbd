"""Get the real data sets: check what is there, fetch what is missing from a mirror.

:func:`fetch_dataset` is what ``slamkit data fetch NAME`` calls; :func:`dataset_status` what
``slamkit data list`` shows. Both read the table of :mod:`slamkit.datasets.sources`.

**Mirror.** The publishers distribute other packagings than the files slamkit knows (see
:mod:`slamkit.datasets.sources`), so files are fetched from a *mirror*: a base URL under which
each file lies at its path relative to the data root (``MIRROR/laser/dpslam/loop5.log.gz``) —
an ``http(s)://`` server, a ``file://`` URL or a local folder (a copy of someone's data
folder). It is set by ``--mirror`` or :data:`MIRROR_ENV_VAR`; there is no default, because no
public mirror of slamkit's data folder exists. Without one, :func:`fetch_dataset` downloads
nothing and reports, for each missing file, its origin and where to put it.

**Nothing half-written.** Each file streams into a temporary file in its target folder while
its SHA-256 is computed; it is moved into place (``os.replace``, atomic on one file system)
only when its size and digest match the table. A refused or dropped download removes the
temporary file and any folder this call created for it, and raises
:class:`~slamkit.errors.FetchError`. Files already present that verify are left untouched.

Why not ``pooch`` (SciPy's downloader, which does the same temp-file-and-hash dance): it
brings ``requests`` (with urllib3, idna, charset-normalizer, certifi) and ``platformdirs``
into a core that needs only NumPy and SciPy, it checks a hash but not a size, it creates
folders it does not remove on failure, it cannot read a ``file://`` or folder mirror, and its
errors would still need translating into slamkit's. What it would save is about sixty lines.
"""

from __future__ import annotations

import hashlib
import http.client
import os
import tempfile
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from slamkit.datasets.checksums import DataFile
from slamkit.datasets.paths import ENV_VAR, find_data_root
from slamkit.datasets.registry import DATASETS, DatasetEntry
from slamkit.datasets.sources import DataSource, Origin, get_source, origin_of
from slamkit.errors import ConfigError, DataNotFoundError, FetchError

__all__ = [
    "MIRROR_ENV_VAR",
    "DatasetStatus",
    "FetchReport",
    "FetchedFile",
    "FileState",
    "check_file",
    "dataset_status",
    "download_file",
    "fetch_dataset",
    "fetch_source",
    "fetch_target_root",
    "file_digest",
    "mirror_url",
]

MIRROR_ENV_VAR = "SLAMKIT_DATA_MIRROR"
"""The environment variable naming the mirror base URL (``--mirror`` wins over it)."""

CHUNK = 1 << 16
"""Bytes read per step while downloading and hashing."""

FileState = Literal["verified", "present", "missing", "wrong size", "wrong checksum"]
"""A file under the data root: ``present`` exists with the right size (not hashed),
``verified`` also has the right SHA-256."""


def file_digest(path: str | Path) -> tuple[int, str]:
    """Size in bytes and SHA-256 (hex) of the file at ``path``."""
    h = hashlib.sha256()
    size = 0
    with Path(path).open("rb") as fh:
        while block := fh.read(CHUNK * 16):
            size += len(block)
            h.update(block)
    return size, h.hexdigest()


def check_file(file: DataFile, root: Path | None, *, verify: bool = False) -> FileState:
    """The state of ``file`` under ``root`` (``None``: no data folder, so missing). Without
    ``verify`` only the size is compared (cheap); with it the SHA-256 too."""
    path = None if root is None else root / file.path
    if path is None or not path.is_file():
        return "missing"
    if path.stat().st_size != file.size:
        return "wrong size"
    if not verify:
        return "present"
    return "verified" if file_digest(path)[1] == file.sha256 else "wrong checksum"


@dataclass(frozen=True)
class DatasetStatus:
    """What ``slamkit data list`` says of one data set: ``files`` how many it needs, and
    how many of them are ``missing`` or ``damaged`` (wrong size, or with ``verified`` a wrong
    checksum). Simulated data sets need none."""

    name: str
    kind: str
    files: int
    missing: int
    damaged: int
    verified: bool

    @property
    def available(self) -> bool:
        """All files there with the right size (and checksum, when verified)."""
        return self.missing == 0 and self.damaged == 0

    def summary(self) -> str:
        """One phrase: ``built in``, ``present``, ``verified``, ``2 of 4 missing``, ...."""
        if self.kind == "simulated":
            return "built in"
        if self.available:
            return "verified" if self.verified else "present"
        parts = []
        if self.missing:
            parts.append(f"{self.missing} of {self.files} missing")
        if self.damaged:
            what = "differ" if self.verified else "have the wrong size"
            parts.append(f"{self.damaged} of {self.files} {what}")
        return ", ".join(parts)


def dataset_status(
    entry: DatasetEntry, data_root: str | Path | None = None, *, verify: bool = False
) -> DatasetStatus:
    """Which of ``entry``'s files are under the data root (:func:`find_data_root` of
    ``data_root``), checked by size or, with ``verify``, by SHA-256. A file the checksum
    table does not know is checked for existence only."""
    if entry.kind == "simulated":
        return DatasetStatus(entry.name, entry.kind, 0, 0, 0, verify)
    root = find_data_root(data_root)
    source = get_source(entry.name)
    states = [check_file(f, root, verify=verify) for f in source.files]
    unknown_missing = sum(root is None or not (root / p).exists() for p in source.unknown)
    return DatasetStatus(
        entry.name,
        entry.kind,
        len(source.paths),
        states.count("missing") + unknown_missing,
        sum(s in ("wrong size", "wrong checksum") for s in states),
        verify,
    )


def mirror_url(explicit: str | None = None) -> str | None:
    """The mirror base URL: ``explicit``, else :data:`MIRROR_ENV_VAR`, else ``None``. A value
    without a scheme is a local folder (it must exist) and becomes a ``file://`` URL; only
    ``http``, ``https`` and ``file`` are accepted (:class:`~slamkit.errors.ConfigError`)."""
    value = explicit if explicit else os.environ.get(MIRROR_ENV_VAR) or None
    if value is None:
        return None
    scheme = urllib.parse.urlsplit(value).scheme.lower()
    if scheme in ("http", "https", "file"):
        return value.rstrip("/")
    if scheme and len(scheme) > 1:  # one letter: a Windows drive, a path
        raise ConfigError(f"mirror {value!r}: expected an http(s):// or file:// URL or a folder")
    folder = Path(value).expanduser()
    if not folder.is_dir():
        raise ConfigError(f"mirror {value!r}: not a folder, and not an http(s):// or file:// URL")
    return folder.resolve().as_uri()


def fetch_target_root(explicit: str | Path | None = None) -> Path:
    """The folder to fetch into: ``explicit`` (``--data-root``), else ``SLAMKIT_DATA`` —
    either is created if it does not exist — else the data folder the other commands find
    (:func:`find_data_root`). None of them: :class:`~slamkit.errors.DataNotFoundError`."""
    if explicit is not None:
        return Path(explicit).expanduser()
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env).expanduser()
    found = find_data_root()
    if found is None:
        raise DataNotFoundError(
            f"no data folder to fetch into: set {ENV_VAR} (it is created if missing) or give "
            "--data-root"
        )
    return found


def download_file(
    url: str,
    target: Path,
    file: DataFile,
    *,
    timeout: float = 60.0,
    progress: Callable[[int], None] | None = None,
) -> None:
    """Download ``url`` to ``target`` (whose folder must exist), all or nothing: the bytes go
    to a temporary file beside ``target`` and replace it only when their size and SHA-256
    are ``file``'s. Otherwise the temporary file is removed and
    :class:`~slamkit.errors.FetchError` says why (HTTP status, dropped connection with the
    byte count, digest mismatch). ``progress(n)`` is called with each block's byte count."""
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
    tmp = Path(tmp_name)
    try:
        digest = hashlib.sha256()
        size = 0
        with os.fdopen(fd, "wb") as out, urllib.request.urlopen(url, timeout=timeout) as response:
            while block := response.read(CHUNK):
                size += len(block)
                if size > file.size:
                    raise FetchError(
                        f"{url}: more than the {file.size} bytes expected arrived; refused",
                        url,
                        target,
                    )
                digest.update(block)
                out.write(block)
                if progress is not None:
                    progress(len(block))
            out.flush()
            os.fsync(out.fileno())
        if size != file.size:
            raise FetchError(
                f"{url}: {size} of {file.size} bytes arrived (connection dropped?); refused",
                url,
                target,
            )
        if digest.hexdigest() != file.sha256:
            raise FetchError(
                f"{url}: SHA-256 {digest.hexdigest()} is not the expected {file.sha256}; "
                "refused (the mirror holds another version of the file)",
                url,
                target,
            )
        os.replace(tmp, target)
    except FetchError:
        raise
    except urllib.error.HTTPError as exc:
        raise FetchError(f"{url}: HTTP {exc.code} {exc.reason}", url, target) from None
    except urllib.error.URLError as exc:
        raise FetchError(f"{url}: {exc.reason}", url, target) from None
    except http.client.IncompleteRead as exc:
        raise FetchError(
            f"{url}: connection dropped after {size + len(exc.partial)} of {file.size} bytes; "
            "refused",
            url,
            target,
        ) from None
    except (OSError, http.client.HTTPException) as exc:
        raise FetchError(f"{url}: {type(exc).__name__}: {exc}", url, target) from None
    finally:
        tmp.unlink(missing_ok=True)


Action = Literal["present", "downloaded", "replaced", "by hand"]


@dataclass(frozen=True)
class FetchedFile:
    """One file of a fetch: where it is (or goes), and what happened: ``present`` (already
    there and verified, left alone), ``downloaded``, ``replaced`` (was there but did not
    verify), ``by hand`` (missing or damaged, no mirror: get it from ``origin``)."""

    file: DataFile
    path: Path
    action: Action
    origin: Origin | None
    url: str | None = None


@dataclass(frozen=True)
class FetchReport:
    """The result of :func:`fetch_dataset`: the data root written into, the mirror used
    (``None``: none set), and every file of the data set with what was done."""

    name: str
    root: Path
    mirror: str | None
    files: tuple[FetchedFile, ...]
    source: DataSource

    @property
    def by_hand(self) -> tuple[FetchedFile, ...]:
        """The files still to get by hand (no mirror was set)."""
        return tuple(f for f in self.files if f.action == "by hand")

    @property
    def downloaded_bytes(self) -> int:
        return sum(f.file.size for f in self.files if f.action in ("downloaded", "replaced"))


def _missing_dirs(folder: Path) -> list[Path]:
    """``folder`` and its ancestors that do not exist yet, deepest first."""
    missing = []
    while not folder.exists():
        missing.append(folder)
        if folder.parent == folder:
            break
        folder = folder.parent
    return missing


def fetch_dataset(
    name: str,
    *,
    data_root: str | Path | None = None,
    mirror: str | None = None,
    timeout: float = 60.0,
    progress: Callable[[int, int], None] | None = None,
) -> FetchReport:
    """Make the files of ``name`` (a registered real data set or a group of
    :mod:`slamkit.datasets.sources`) present and verified under the data root
    (:func:`fetch_target_root`). Each file is hashed; one that verifies is left alone; one
    that is missing or damaged is downloaded from ``mirror`` (:func:`mirror_url`) with
    :func:`download_file`. Without a mirror nothing is downloaded and such files are
    reported ``by hand``. ``progress(done_bytes, total_bytes)`` follows the downloads.

    Raises :class:`~slamkit.errors.UnknownNameError` for a name that is neither,
    :class:`~slamkit.errors.InputError` for a simulated data set (nothing to fetch) or a
    registered file with no checksum, and :class:`~slamkit.errors.FetchError` at the first
    file that cannot be fetched (files fetched before it stay: they are verified; the
    failed one and any folder made for it are removed)."""
    from slamkit.errors import InputError

    entry = DATASETS.get(name)
    if entry is not None and entry.kind == "simulated":
        raise InputError(f"{name!r} is simulated: it is built in, there is nothing to fetch")
    source = get_source(name)
    if source.unknown:
        raise InputError(
            f"{name!r}: no size and checksum known for {', '.join(source.unknown)} "
            "(slamkit.datasets.checksums)"
        )
    return fetch_source(
        source,
        fetch_target_root(data_root),
        mirror_url(mirror),
        timeout=timeout,
        progress=progress,
    )


def fetch_source(
    source: DataSource,
    root: Path,
    base: str | None,
    *,
    timeout: float = 60.0,
    progress: Callable[[int, int], None] | None = None,
) -> FetchReport:
    """The work of :func:`fetch_dataset` on resolved arguments: ``source``'s files under
    ``root`` (created when needed), fetched from the mirror base URL ``base`` (``None``:
    report the missing files ``by hand``, download nothing, create nothing)."""
    todo: list[DataFile] = []
    done: dict[str, Action] = {}
    for f in source.files:
        state = check_file(f, root, verify=True)
        if state == "verified":
            done[f.path] = "present"
        else:
            todo.append(f)
            done[f.path] = (
                "by hand" if base is None else ("downloaded" if state == "missing" else "replaced")
            )
    urls: dict[str, str] = {}
    if base is not None and todo:
        total = sum(f.size for f in todo)
        fetched = 0

        def step(n: int) -> None:
            nonlocal fetched
            fetched += n
            if progress is not None:
                progress(fetched, total)

        for f in todo:
            urls[f.path] = f"{base}/{urllib.parse.quote(f.path)}"
            target = root / f.path
            created = _missing_dirs(target.parent)
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                download_file(urls[f.path], target, f, timeout=timeout, progress=step)
            except BaseException:
                for folder in created:  # deepest first; only the empty ones this call made
                    try:
                        folder.rmdir()
                    except OSError:
                        break
                raise
    files = tuple(
        FetchedFile(f, root / f.path, done[f.path], origin_of(f.path), urls.get(f.path))
        for f in source.files
    )
    return FetchReport(source.name, root, base, files, source)
