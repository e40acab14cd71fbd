"""Fetching data sets from a mirror: real downloads from an HTTP server on 127.0.0.1.

Most tests serve a small temporary folder whose checksums the test computes, so they run
without the shared data; the ones marked ``realdata`` serve the shared data folder itself and
check the checksum table against it.
"""

from __future__ import annotations

import hashlib
import http.server
import os
import re
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.datasets import DATASETS
from slamkit.datasets.checksums import FILES, DataFile
from slamkit.datasets.fetch import (
    MIRROR_ENV_VAR,
    check_file,
    dataset_status,
    fetch_dataset,
    fetch_source,
    mirror_url,
)
from slamkit.datasets.sources import (
    GROUPS,
    NOT_STATED,
    DataSource,
    fetchable_names,
    get_source,
    origin_of,
)
from slamkit.errors import ConfigError, FetchError, InputError, UnknownNameError

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


@dataclass
class Mirror:
    """A running HTTP server over ``folder``: ``url`` its base, ``requests`` the paths asked
    for, ``truncate`` paths whose body is cut after half its bytes (with the full
    Content-Length) before the connection is closed."""

    folder: Path
    url: str = ""
    requests: list[str] = field(default_factory=list)
    truncate: set[str] = field(default_factory=set)


class _Handler(http.server.SimpleHTTPRequestHandler):
    mirror: Mirror

    def do_GET(self) -> None:
        self.mirror.requests.append(self.path.lstrip("/"))
        if self.path.lstrip("/") in self.mirror.truncate:
            body = (self.mirror.folder / self.path.lstrip("/")).read_bytes()
            self.send_response(200)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body[: len(body) // 2])
            self.wfile.flush()
            self.close_connection = True
            return
        super().do_GET()

    def log_message(self, format: str, *args: object) -> None:  # quiet test output
        pass


@pytest.fixture
def serve() -> Iterator[partial[Mirror]]:
    """``serve(folder)`` starts a server over ``folder``; all are shut down after the test."""
    servers: list[http.server.ThreadingHTTPServer] = []

    def start(folder: Path) -> Mirror:
        mirror = Mirror(folder)
        handler = type("Handler", (_Handler,), {"mirror": mirror})
        server = http.server.ThreadingHTTPServer(
            ("127.0.0.1", 0), partial(handler, directory=str(folder))
        )
        threading.Thread(target=server.serve_forever, daemon=True).start()
        servers.append(server)
        mirror.url = f"http://127.0.0.1:{server.server_address[1]}"
        return mirror

    yield partial(start)
    for server in servers:
        server.shutdown()
        server.server_close()


def _file(folder: Path, rel: str, content: bytes) -> DataFile:
    """Write ``content`` at ``folder/rel`` and return its table entry."""
    path = folder / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(content)
    return DataFile(rel, len(content), hashlib.sha256(content).hexdigest())


@pytest.fixture
def small(tmp_path: Path) -> tuple[Path, DataSource]:
    """A mirror folder with two small files in nested folders and their source."""
    folder = tmp_path / "mirror"
    files = (
        _file(folder, "laser/small/a.log.gz", b"\x1f\x8b" + bytes(range(256)) * 40),
        _file(folder, "landmarks/b.txt", b"1.0 2.0 3.0\n" * 500),
    )
    return folder, DataSource("small", "two test files", files)


def _leftovers(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*")) if root.exists() else []


def test_fetch_downloads_verifies_and_reports_where(serve, small, tmp_path):
    folder, source = small
    mirror = serve(folder)
    root = tmp_path / "data"  # does not exist yet: the fetch creates it
    seen: list[tuple[int, int]] = []
    report = fetch_source(source, root, mirror.url, progress=lambda d, t: seen.append((d, t)))
    assert report.root == root and report.mirror == mirror.url
    assert [f.action for f in report.files] == ["downloaded", "downloaded"]
    for fetched in report.files:
        assert fetched.path == root / fetched.file.path
        assert fetched.path.read_bytes() == (folder / fetched.file.path).read_bytes()
        assert check_file(fetched.file, root, verify=True) == "verified"
        assert fetched.url == f"{mirror.url}/{fetched.file.path}"
    assert report.downloaded_bytes == source.size
    assert seen[-1] == (source.size, source.size)
    assert sorted(mirror.requests) == sorted(f.path for f in source.files)
    # no temporary file left beside the downloads
    assert not [p for p in _leftovers(root) if p.endswith(".part")]


def test_wrong_checksum_is_refused_and_leaves_nothing(serve, small, tmp_path):
    folder, source = small
    good = source.files[0]
    (folder / good.path).write_bytes(b"X" * good.size)  # same size, other bytes
    mirror = serve(folder)
    root = tmp_path / "data"
    with pytest.raises(FetchError, match=r"SHA-256 \w+ is not the expected") as info:
        fetch_source(DataSource("bad", "", (good,)), root, mirror.url)
    assert info.value.path == root / good.path
    assert not root.exists()  # not the file, not the folders made for it, not the root


def test_wrong_checksum_keeps_existing_folders(serve, small, tmp_path):
    folder, source = small
    good = source.files[0]
    (folder / good.path).write_bytes(b"X" * good.size)
    mirror = serve(folder)
    root = tmp_path / "data"
    (root / "laser").mkdir(parents=True)
    (root / "laser" / "other.txt").write_text("mine")
    with pytest.raises(FetchError):
        fetch_source(DataSource("bad", "", (good,)), root, mirror.url)
    assert _leftovers(root) == ["laser", "laser/other.txt"]


def test_dropped_connection_is_refused_and_leaves_nothing(serve, small, tmp_path):
    folder, source = small
    mirror = serve(folder)
    mirror.truncate.add(source.files[0].path)
    root = tmp_path / "data"
    with pytest.raises(FetchError, match=rf"of {source.files[0].size} bytes"):
        fetch_source(DataSource("cut", "", (source.files[0],)), root, mirror.url)
    assert mirror.requests == [source.files[0].path]
    assert not root.exists()


def test_missing_file_on_the_mirror_is_an_http_error(serve, small, tmp_path):
    folder, source = small
    (folder / source.files[1].path).unlink()
    mirror = serve(folder)
    root = tmp_path / "data"
    with pytest.raises(FetchError, match="HTTP 404"):
        fetch_source(source, root, mirror.url)
    # the first file was fetched and verified before the failure, and stays
    assert _leftovers(root) == ["laser", "laser/small", "laser/small/a.log.gz"]


def test_present_files_are_skipped_and_damaged_ones_replaced(serve, small, tmp_path):
    folder, source = small
    mirror = serve(folder)
    root = tmp_path / "data"
    first, second = source.files
    _file(root, first.path, (folder / first.path).read_bytes())
    os.utime(root / first.path, (1_000_000, 1_000_000))
    _file(root, second.path, b"?" * second.size)  # damaged: right size, wrong bytes
    assert check_file(second, root) == "present"  # by size only
    assert check_file(second, root, verify=True) == "wrong checksum"
    report = fetch_source(source, root, mirror.url)
    assert [f.action for f in report.files] == ["present", "replaced"]
    assert mirror.requests == [second.path]
    assert (root / first.path).stat().st_mtime == 1_000_000
    assert check_file(second, root, verify=True) == "verified"
    again = fetch_source(source, root, mirror.url)
    assert [f.action for f in again.files] == ["present", "present"]
    assert mirror.requests == [second.path]


def test_without_a_mirror_nothing_is_downloaded_and_the_origin_is_named(tmp_path):
    root = tmp_path / "data"
    report = fetch_source(get_source("loop5"), root, None)
    assert [f.action for f in report.by_hand] == ["by hand"]
    hand = report.by_hand[0]
    assert hand.path == root / "laser/dpslam/loop5.log.gz"
    assert hand.origin is not None and "dpslam" in hand.origin.url
    assert not root.exists()


def test_mirror_setting(tmp_path, monkeypatch):
    monkeypatch.delenv(MIRROR_ENV_VAR, raising=False)
    assert mirror_url(None) is None
    monkeypatch.setenv(MIRROR_ENV_VAR, "https://example.org/slamkit-data/")
    assert mirror_url(None) == "https://example.org/slamkit-data"
    assert mirror_url("http://127.0.0.1:8000") == "http://127.0.0.1:8000"  # the option wins
    assert mirror_url(str(tmp_path)) == tmp_path.resolve().as_uri()
    with pytest.raises(ConfigError, match="not a folder"):
        mirror_url(str(tmp_path / "nope"))
    with pytest.raises(ConfigError, match="expected an http"):
        mirror_url("ftp://example.org/data")


def test_names_that_cannot_be_fetched(tmp_path):
    with pytest.raises(InputError, match="simulated"):
        fetch_dataset("five-features", data_root=tmp_path)
    with pytest.raises(UnknownNameError, match="corrected-carmen"):
        fetch_dataset("no-such-set", data_root=tmp_path)


def test_every_real_data_set_has_a_source():
    """A real data set cannot be registered without its files in the checksum table and an
    origin (publisher, URL, citation, licence) for each."""
    for entry in DATASETS.values():
        source = get_source(entry.name)
        if entry.kind == "simulated":
            assert source.files == () and source.unknown == ()
            continue
        assert source.unknown == (), f"{entry.name}: add these files to checksums.py"
        assert source.paths == entry.files
        for path in source.paths:
            origin = origin_of(path)
            assert origin is not None, f"{path}: no origin in sources.ORIGINS"
            assert origin.url.startswith(("http://", "https://"))
            assert origin.citation and origin.licence and origin.publisher


def test_every_file_of_the_table_has_an_origin_and_a_name():
    fetchable = {p for n in fetchable_names() for p in get_source(n).paths}
    for path in FILES:
        assert origin_of(path) is not None, path
        assert path in fetchable, f"{path}: in no data set or group"
    carmen = [f.path.split("/")[-1] for f in get_source("corrected-carmen").files]
    assert len(carmen) == 11 and "seattle-corrected.log.gz" in carmen
    assert len(get_source("victoria-park-laser").files) == 4
    assert len(get_source("victoria-park-raw").files) == 5
    assert set(GROUPS) <= set(fetchable_names()) | set(DATASETS)
    licences = {origin_of(p).licence for p in FILES}  # type: ignore[union-attr]
    assert NOT_STATED in licences


def test_docs_name_every_data_set_and_group():
    text = (ROOT / "docs" / "data.md").read_text(encoding="utf-8")
    for name in [*DATASETS, *GROUPS]:
        assert f"`{name}`" in text, f"docs/data.md does not mention {name}"


def test_data_list_says_present_missing_and_damaged(tmp_path):
    entry = DATASETS["loop5"]
    (file,) = get_source("loop5").files
    assert dataset_status(entry, tmp_path).summary() == "1 of 1 missing"
    res = runner.invoke(app, ["data", "list", "--data-root", str(tmp_path)], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    row = next(line for line in res.output.splitlines() if " loop5 " in line)
    assert "1 of 1 missing" in row and " no " in row
    assert re.search(r"five-features\s.*built in", res.output)
    _file(tmp_path, file.path, b"\0" * file.size)  # right size, wrong content
    assert dataset_status(entry, tmp_path).summary() == "present"
    res = runner.invoke(
        app, ["data", "list", "--data-root", str(tmp_path), "--verify"], env={"COLUMNS": "200"}
    )
    row = next(line for line in res.output.splitlines() if " loop5 " in line)
    assert "1 of 1 differ" in row and " no " in row


def test_cli_fetch_refuses_a_bad_file_with_one_line(serve, tmp_path):
    (file,) = get_source("loop5").files
    folder = tmp_path / "mirror"
    _file(folder, file.path, b"\0" * file.size)
    mirror = serve(folder)
    root = tmp_path / "data"
    res = runner.invoke(
        app, ["data", "fetch", "loop5", "--mirror", mirror.url, "--data-root", str(root)]
    )
    assert res.exit_code == 1
    errors = [line for line in res.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "SHA-256" in errors[0] and "refused" in errors[0]
    assert not root.exists()


def test_cli_fetch_without_mirror_says_where_to_get_each_file(tmp_path, monkeypatch):
    monkeypatch.delenv(MIRROR_ENV_VAR, raising=False)
    root = tmp_path / "data"
    res = runner.invoke(
        app, ["data", "fetch", "intel-raw", "--data-root", str(root)], env={"COLUMNS": "300"}
    )
    assert res.exit_code == 1
    for f in get_source("intel-raw").files:
        assert str(root / f.path) in res.output and f.sha256 in res.output
    assert "slamevaluation" in res.output and "no mirror set" in res.output
    assert not root.exists()


@pytest.mark.realdata
def test_checksum_table_matches_the_data_folder(data_root):
    """The evidence behind the table: every file's size and SHA-256 as the data folder has
    it (regenerate with scripts/data_checksums.py when the folder changes)."""
    from slamkit.datasets.fetch import file_digest

    for path, file in FILES.items():
        assert file_digest(data_root / path) == (file.size, file.sha256), path


@pytest.mark.realdata
def test_cli_fetches_a_real_data_set_over_http(serve, data_root, tmp_path):
    mirror = serve(data_root)
    root = tmp_path / "data"
    res = runner.invoke(
        app,
        ["data", "fetch", "intel-raw", "--mirror", mirror.url, "--data-root", str(root)],
        env={"COLUMNS": "300"},
    )
    assert res.exit_code == 0, res.output
    from slamkit.datasets.fetch import file_digest

    for f in get_source("intel-raw").files:
        assert file_digest(root / f.path) == (f.size, f.sha256)
        assert f"downloaded {root / f.path}" in res.output
    assert dataset_status(DATASETS["intel-raw"], root, verify=True).summary() == "verified"
    res = runner.invoke(
        app, ["data", "fetch", "intel-raw", "--mirror", mirror.url, "--data-root", str(root)]
    )
    assert res.exit_code == 0 and "2 of 2 files already present" in res.output
