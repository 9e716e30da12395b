"""`polyrob synth` writes a controller whose certificate `polyrob analyze` reproduces.

Short syntheses (one D-K iteration, one fixed-structure iteration from K*)
keep the file near a minute on two cores; the certificate is what matters
here, not how good the controller is.
"""

from __future__ import annotations

import json

import pytest

from polyrob.cli import main

PAPER = ["paper_2r", "--domain", "paper"]


def _synth_then_analyze(tmp_path, capsys, *synth_options):
    out = tmp_path / "K.json"
    assert main(["synth", *PAPER, *synth_options, "--quiet", "-o", str(out)]) == 0
    capsys.readouterr()
    certificate = json.loads(out.read_text())["certificate"]
    assert main(["analyze", *PAPER, "--controller", str(out), "--mc", "20", "--quiet", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    return certificate, report


@pytest.mark.parametrize(
    "options, structure",
    [
        (("--complex", "--max-iter", "1"), "full"),
        (("--structure", "tf3", "--init", "paper", "--starts", "1", "--max-iter", "1"), "tf3"),
    ],
    ids=["full-order", "tf3"],
)
def test_analyze_reproduces_the_synth_certificate(tmp_path, capsys, options, structure):
    certificate, report = _synth_then_analyze(tmp_path, capsys, *options)
    assert certificate["structure"] == structure
    rp = report["robust_performance"]
    # two independent sweeps (synthesis grid vs analysis grid, both peak-refined)
    assert rp["mu_upper"] == pytest.approx(certificate["peak_mu_upper"], rel=2e-3)
    assert rp["mu_lower"] == pytest.approx(certificate["peak_mu_lower"], rel=2e-3)
    assert report["parameters"] == 10 and report["nominal_stability"] is True


def test_bad_structure_leaves_no_controller_file(tmp_path, capsys):
    out = tmp_path / "K.json"
    code = main(["synth", *PAPER, "--structure", "tf0x", "--quiet", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "structure" in err
    assert not out.exists() and list(tmp_path.iterdir()) == []
