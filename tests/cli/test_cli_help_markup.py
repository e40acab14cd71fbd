"""Help text through rich markup: typer renders every help string as rich markup, which takes
``[rerun]`` or ``[m]`` for a tag and drops it (``pip install 'slamkit'``). Every bracketed
word written in a command's or option's help must appear on its rendered help screen."""

from __future__ import annotations

import re

import typer
from typer.testing import CliRunner

from slamkit.cli.main import app

runner = CliRunner()


def _commands(command, path=()):
    yield path, command
    for name, sub in getattr(command, "commands", {}).items():
        yield from _commands(sub, (*path, name))


def _bracketed(text: str) -> list[str]:
    """The ``[word]`` a reader is meant to see (rich's escape ``\\[`` shown as ``[``)."""
    return re.findall(r"\[[^\]\s]+\]", text.replace("\\[", "["))


def test_every_bracketed_word_of_the_help_is_shown():
    checked = []
    for path, command in _commands(typer.main.get_command(app)):
        texts = [command.help or ""] + [getattr(p, "help", None) or "" for p in command.params]
        wanted = {w for t in texts for w in _bracketed(t)}
        if not wanted:
            continue
        res = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "400"})
        assert res.exit_code == 0, res.output
        for word in sorted(wanted):
            assert word in res.output, (path, word)
            checked.append((path, word))
    assert (("run",), "[rerun]") in checked  # the extra to install, not 'slamkit'
    assert (("map", "occupancy"), "[mapping.model]") in checked
    assert len(checked) >= 10


def test_run_help_names_the_rerun_extra():
    res = runner.invoke(app, ["run", "--help"], env={"COLUMNS": "400"})
    assert "pip install 'slamkit[rerun]'" in res.output
