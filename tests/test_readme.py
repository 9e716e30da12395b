"""The README as a newcomer reads it: its commands parse, its "your robot" and "export" steps run as written.

Every `polyrob` command of the README's ```bash blocks parses with the CLI;
the commands of the sections "Next: your robot and your task" and "Next:
export" run one after the other in a fresh folder, as a newcomer types them
(those on the placeholder ``my_arm.urdf`` only parse); and README.md carries
no commit hash and no load average (measurements live in
``benchmarks/results/*.json`` and the docs generated from them).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from polyrob.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
# the one parser of the README's commands: the benchmark that times them has it
sys.path.insert(0, str(ROOT / "benchmarks"))
from readme_commands import readme_commands as _readme_commands  # noqa: E402

COMMANDS = _readme_commands()
#: the README's newcomer path after the two first commands, in this order
NEWCOMER_SECTIONS = ("## Next: your robot and your task", "## Next: export")
PLACEHOLDER = "my_arm.urdf"  # the user's own file: shown, parsed, not run


def section_commands(text: str, heading: str) -> list[str]:
    """The `polyrob ...` commands of the ```bash blocks between ``heading`` and the next ``## `` heading."""
    start = text.index(heading)
    end = text.find("\n## ", start + len(heading))
    body = text[start : end if end >= 0 else None]
    out = []
    for block in re.findall(r"```bash\n(.*?)```", body, flags=re.S):
        for line in block.splitlines():
            line = line.split("  #")[0].strip()
            out += [p.strip() for p in line.split("&&") if p.strip().startswith("polyrob ")]
    return out


def forbidden_history(text: str) -> list[str]:
    """Commit hashes (7-40 hex digits with a digit and a letter) and load averages in ``text``."""
    found = [m.group(0) for m in re.finditer(r"\b[0-9a-f]{7,40}\b", text) if re.search(r"\d", m.group(0))]
    found = [h for h in found if re.search(r"[a-f]", h)]
    found += re.findall(r"load average", text, flags=re.I)
    return found


def test_the_readme_shows_commands():
    assert len(COMMANDS) >= 5 and any(c.split()[1] == "run" for c in COMMANDS)


def test_the_two_first_commands_are_the_main_job_and_the_tests():
    first_block = re.search(r"```bash\n(.*?)```", README.read_text(), flags=re.S).group(1).splitlines()
    assert first_block[0].startswith("pip install -e . && polyrob run ")
    assert first_block[1].startswith('pip install -e ".[test]" && python -m pytest -q ')


def test_ci_runs_exactly_the_readmes_test_command():
    first_block = re.search(r"```bash\n(.*?)```", README.read_text(), flags=re.S).group(1).splitlines()
    pytest_command = first_block[1].split("#")[0].split("&&")[1].strip()  # python -m pytest -q -n 2 --dist worksteal
    ci = (ROOT / ".ci" / "run").read_text()
    assert f'python -m pip install -q -e ".[test]" && {pytest_command}\n' in ci


@pytest.mark.parametrize("command", COMMANDS)
def test_each_readme_command_parses_as_written(command):
    args = build_parser().parse_args(shlex.split(command)[1:])  # SystemExit(2) on an unknown option or bad value
    assert callable(args.func)


@pytest.mark.parametrize("sub", sorted({c.split()[1] for c in COMMANDS}))
def test_each_subcommand_help_runs(sub, capsys):
    with pytest.raises(SystemExit) as exc:
        main([sub, "--help"])
    assert exc.value.code == 0 and "usage: polyrob " + sub in capsys.readouterr().out


def test_readme_has_no_commit_hash_and_no_load_average():
    assert forbidden_history(README.read_text()) == []


@pytest.mark.parametrize(
    "text, found",
    [
        ("measured at commit b58565f on 2026-11-27", ["b58565f"]),
        ("the same at 0161d79a9c (19.2 min)", ["0161d79a9c"]),
        ("load average 0.2 and 0.8", ["load average"]),
        ("order 8, mu <= 0.9449, decade 1000000, word deadbeef", []),
    ],
)
def test_the_history_check_finds_hashes_and_loads(text, found):
    assert forbidden_history(text) == found


def test_the_newcomer_sections_show_the_steps():
    text = README.read_text()
    robot, export = (section_commands(text, h) for h in NEWCOMER_SECTIONS)
    assert any("--pose" in c and "-o K.json" in c and PLACEHOLDER not in c for c in robot)
    assert any(c.startswith("polyrob export K.json ") for c in export)


@pytest.mark.timeout(600)  # about 90 s on an idle 2-core machine; the limit only guards against a hang
def test_the_newcomer_path_runs_as_written(tmp_path):
    text = README.read_text()
    commands = [c for h in NEWCOMER_SECTIONS for c in section_commands(text, h) if PLACEHOLDER not in c]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")]))
    for command in commands:
        argv = [sys.executable, "-m", "polyrob.cli", *shlex.split(command)[1:]]
        proc = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, env=env)
        assert proc.returncode == 0, f"{command}: exit {proc.returncode}: {proc.stderr[-2000:]}"
        if " synth " in f" {command} ":
            assert "verdict: robust performance CERTIFIED" in proc.stdout
    record = json.loads((tmp_path / "K.json").read_text())
    assert record["certificate"]["status"] == "CERTIFIED"
    assert {"controller.h", "controller.c", "controller.json"} <= {p.name for p in (tmp_path / "ctrl").iterdir()}
    assert "controller_step" in (tmp_path / "ctrl" / "controller.h").read_text()
