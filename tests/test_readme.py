"""Every `polyrob` command the README shows parses as written (options, values), and each subcommand's --help runs."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from polyrob.cli import build_parser, main

README = Path(__file__).resolve().parents[1] / "README.md"


def _readme_commands() -> list[str]:
    blocks = re.findall(r"```bash\n(.*?)```", README.read_text(), flags=re.S)
    out = []
    for block in blocks:
        for line in block.splitlines():
            line = line.split("  #")[0].strip()
            for part in line.split("&&"):
                part = part.strip()
                if part.startswith("polyrob "):
                    out.append(part)
    return out


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
