"""Output paths are checked before the work starts: one line, exit 2, nothing written."""

from __future__ import annotations

import subprocess

import pytest

from polyrob.cli import main


@pytest.fixture
def no_work(monkeypatch):
    """Any bounding or synthesis would fail the test: the path must be refused first."""
    import polyrob.bounds.pldi
    import polyrob.synthesis

    def boom(*args, **kwargs):
        raise AssertionError("work started before the output path was checked")

    monkeypatch.setattr(polyrob.bounds.pldi, "bound_pldi", boom)
    monkeypatch.setattr(polyrob.synthesis, "musyn", boom)


def _bad_paths(tmp_path):
    afile = tmp_path / "file.txt"
    afile.write_text("x")
    return [
        (str(tmp_path / "adir"), "is a directory"),
        ("/proc/polyrob_out.json", "/proc"),
        ("/sys/polyrob_out.json", "/sys"),
        (str(afile / "out.json"), "is a file, not a directory"),
    ]


@pytest.mark.parametrize("command", [["bounds", "paper_2r"], ["synth", "paper_2r"], ["run", "paper_2r"]])
def test_bad_output_paths_are_refused_before_any_work(tmp_path, capsys, no_work, command):
    (tmp_path / "adir").mkdir()
    bad = _bad_paths(tmp_path)
    if command[0] == "run":  # run -o DIR writes a run directory: an existing one is fine, a file is not
        bad = [(p, n) for p, n in bad if "adir" not in p] + [(str(tmp_path / "file.txt"), "not a directory")]
    for path, needle in bad:
        before = sorted(p.name for p in tmp_path.rglob("*"))
        code = main([*command, "--quiet", "-o", path])
        out, err = capsys.readouterr()
        assert code == 2 and needle in err and err.count("\n") == 1 and "-o" in err
        assert "[1/" not in out  # no stage started
        assert sorted(p.name for p in tmp_path.rglob("*")) == before  # nothing written (no stray .npz)


def test_console_script_refuses_a_directory(tmp_path):
    done = subprocess.run(
        ["polyrob", "bounds", "paper_2r", "-o", str(tmp_path)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 2 and "is a directory" in done.stderr and done.stderr.count("\n") == 1
    assert list(tmp_path.iterdir()) == []
