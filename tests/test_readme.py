"""README.md's commands run as written, twice in a row, from a fresh folder.

Every ```sh block of README.md carries a marker comment (the convention is written at the
top of README.md): ``run`` blocks are run here, ``data NAMES`` blocks when the named data
sets are present (else skipped with the reason), ``skip REASON`` blocks never (set-up,
placeholders for the reader's files); ``file NAME`` writes the next block's text to NAME.
A runnable line is a ``.venv/bin/slamkit …`` command; it is split as the shell splits it
(:func:`shlex.split`: quotes, ``#`` comments, backslash continuations, one ``> FILE``) and
run in this process through the CLI's app, which is what the console script calls — the
same exit code, without starting an interpreter per line.
"""

from __future__ import annotations

import re
import shlex
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.datasets import find_data_root
from slamkit.datasets.paths import find_data_file
from slamkit.datasets.registry import DATASETS, dataset_available

README = Path(__file__).resolve().parents[1] / "README.md"
PROGRAM = ".venv/bin/slamkit"
KINDS = ("run", "data", "skip", "file")
_MARKER = re.compile(r"^<!--\s*readme-test:\s*(\S+)\s*(.*?)\s*-->\s*$")

runner = CliRunner()


@dataclass(frozen=True)
class Block:
    """A fenced block of README.md and the marker before it (``kind`` None: unmarked)."""

    line: int
    lang: str
    text: str
    kind: str | None
    arg: str


def readme_blocks(text: str) -> list[Block]:
    """The fenced blocks of a markdown text, each with the marker comment on the last
    non-blank line before its opening fence (if any)."""
    blocks: list[Block] = []
    lines = text.splitlines()
    i, marker = 0, None
    while i < len(lines):
        line = lines[i]
        if line.startswith("```"):
            start, lang = i, line[3:].strip()
            i += 1
            while i < len(lines) and not lines[i].startswith("```"):
                i += 1
            body = "\n".join(lines[start + 1 : i]) + "\n"
            kind, arg = marker if marker else (None, "")
            blocks.append(Block(start + 1, lang, body, kind, arg))
            marker = None
        elif line.strip():
            m = _MARKER.match(line.strip())
            marker = (m.group(1), m.group(2)) if m else None
        i += 1
    return blocks


@dataclass(frozen=True)
class Command:
    line: int
    argv: tuple[str, ...]
    stdout_to: str | None


def block_commands(block: Block) -> list[Command]:
    """The commands of a runnable block, continuation lines joined; a line that is not a
    ``.venv/bin/slamkit`` command or uses ``$`` fails the test (see the module docstring)."""
    commands: list[Command] = []
    pending, first = "", 0
    for k, raw in enumerate(block.text.splitlines()):
        if not pending:
            first = block.line + 1 + k
        if raw.rstrip().endswith("\\"):
            pending += raw.rstrip()[:-1] + " "
            continue
        line, pending = pending + raw, ""
        tokens = shlex.split(line, comments=True)
        if not tokens:
            continue
        where = f"README.md line {first}"
        assert "$" not in line.split("#", 1)[0], f"{where}: no $ expansions ({line.strip()})"
        assert tokens[0] == PROGRAM, f"{where}: a runnable block holds {PROGRAM} commands only"
        out = None
        if ">" in tokens:
            at = tokens.index(">")
            assert at == len(tokens) - 2, f"{where}: one '> FILE' at the end, nothing else"
            out, tokens = tokens[at + 1], tokens[:at]
        commands.append(Command(first, tuple(tokens[1:]), out))
    assert not pending, f"README.md block at line {block.line}: ends in a continuation"
    return commands


def _run_blocks(blocks: list[Block], kinds: tuple[str, ...], folder: Path) -> int:
    """Run the blocks of ``kinds`` in order in ``folder`` (a ``file`` block written where it
    stands); returns how many commands ran."""
    count = 0
    for block in blocks:
        if block.kind == "file":
            (folder / block.arg).write_text(block.text, encoding="utf-8")
        if block.kind not in kinds:
            continue
        for cmd in block_commands(block):
            res = runner.invoke(app, list(cmd.argv))
            shown = " ".join(cmd.argv)
            assert res.exit_code == 0, (
                f"README.md line {cmd.line}: slamkit {shown} exited {res.exit_code}\n"
                f"{res.output}\n{res.exception!r}"
            )
            if cmd.stdout_to is not None:
                (folder / cmd.stdout_to).write_text(res.stdout, encoding="utf-8")
            count += 1
    return count


def _missing_data(names: str) -> list[str]:
    missing = []
    for name in names.split():
        entry = DATASETS.get(name)
        present = dataset_available(entry) if entry else find_data_file(name) is not None
        if not present:
            missing.append(name)
    return missing


BLOCKS = readme_blocks(README.read_text(encoding="utf-8"))


def test_every_command_block_is_marked():
    sh = [b for b in BLOCKS if b.lang == "sh"]
    assert len(sh) >= 4
    for b in BLOCKS:
        if b.lang == "sh":
            assert b.kind in ("run", "data", "skip"), f"README.md line {b.line}: no marker"
        assert b.kind in (*KINDS, None), f"README.md line {b.line}: unknown marker {b.kind}"
        if b.kind in ("skip", "data", "file"):
            assert b.arg, f"README.md line {b.line}: '{b.kind}' needs its reason, names or file"
        if b.kind in ("run", "data"):
            assert block_commands(b), f"README.md line {b.line}: a runnable block without commands"
            # what the reader pastes is read by a shell: its syntax is checked by one
            check = subprocess.run(["bash", "-n"], input=b.text, text=True, capture_output=True)
            assert check.returncode == 0, f"README.md line {b.line}: {check.stderr}"
    # every eval example's files come from a run shown before it in the same runnable blocks
    shown: list[str] = []
    for b in BLOCKS:
        if b.kind != "run":
            continue
        for cmd in block_commands(b):
            if cmd.argv[:2] in (("eval", "ape"), ("eval", "rpe")):
                for path in cmd.argv[2:4]:
                    folder = path.split("/")[1]
                    assert folder in shown, f"README.md line {cmd.line}: no run writes {path}"
            if cmd.argv[0] == "run":
                est = cmd.argv[1]
                data = cmd.argv[cmd.argv.index("--data") + 1] if "--data" in cmd.argv else None
                if data:
                    shown.append(f"{est}-{data}")


def test_the_commands_run_twice_in_a_row_from_a_fresh_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    first = _run_blocks(BLOCKS, ("run",), tmp_path)
    assert first >= 10
    assert _run_blocks(BLOCKS, ("run",), tmp_path) == first
    # the second time wrote fresh folders beside the first ones, never into them
    results = tmp_path / "results"
    assert (results / "ekf-slam-five-features-3" / "trajectory.tum").is_file()
    a = (results / "ekf-slam-five-features" / "trajectory.tum").read_bytes()
    for n in (2, 3, 4):  # the re-runs and the second pass: the same bytes
        assert (results / f"ekf-slam-five-features-{n}" / "trajectory.tum").read_bytes() == a


@pytest.mark.realdata
@pytest.mark.slow
@pytest.mark.parametrize(
    "block", [b for b in BLOCKS if b.kind == "data"], ids=lambda b: str(b.line)
)
def test_the_real_data_commands_run_twice(block, tmp_path, monkeypatch):
    if find_data_root() is None:
        pytest.skip("real data not found: set SLAMKIT_DATA to the shared data folder")
    missing = _missing_data(block.arg)
    if missing:
        pytest.skip(f"README.md line {block.line} needs data that is not here: {missing}")
    monkeypatch.chdir(tmp_path)
    first = _run_blocks([block], ("data",), tmp_path)
    assert _run_blocks([block], ("data",), tmp_path) == first > 0
