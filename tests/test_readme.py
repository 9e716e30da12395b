"""Every `polyrob` command the README shows parses as written (options, values), and each subcommand's --help runs."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import pytest

from polyrob.cli import build_parser, main

README = Path(__file__).resolve().parents[1] / "README.md"
# the one parser of the README's commands: the benchmark that times them has it
sys.path.insert(0, str(README.parent / "benchmarks"))
from readme_commands import readme_commands as _readme_commands  # noqa: E402

COMMANDS = _readme_commands()


def test_the_readme_shows_commands():
    assert len(COMMANDS) >= 10 and any(c.split()[1] == "run" for c in COMMANDS)


@pytest.mark.parametrize("command", COMMANDS)
def test_each_readme_command_parses_as_written(command):
    args = build_parser().parse_args(shlex.split(command)[1:])  # SystemExit(2) on an unknown option or bad value
    assert callable(args.func)


@pytest.mark.parametrize("sub", sorted({c.split()[1] for c in COMMANDS}))
def test_each_subcommand_help_runs(sub, capsys):
    with pytest.raises(SystemExit) as exc:
        main([sub, "--help"])
    assert exc.value.code == 0 and "usage: polyrob " + sub in capsys.readouterr().out
