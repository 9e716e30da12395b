"""Every status and verdict is decided in ``polyrob.analysis.certificate``, and nowhere else.

The checks read the source (``ast``, docstrings skipped): outside
``analysis/certificate.py`` no code chooses a :class:`Status` member (it may
compare a decided status with one: that reads it), builds a
:class:`Certificate`, rewrites a status with ``replace(..., status=...)``,
spells a status or a met/pass/fail verdict as a string, calls the ``decide_*``
functions, or derives the facts it passes to ``certificate.py`` from the
words of a sentence (``startswith``/``endswith``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "polyrob"
DECIDER = PACKAGE / "analysis" / "certificate.py"

STATUS_MEMBERS = {"CERTIFIED", "GRID_ONLY", "NOT_CERTIFIED", "VIOLATED"}
#: Verdict words compared case-insensitively (a status spelt in lower case is still a status).
VERDICT_WORDS = {"met", "not met", "pass", "fail", "not certified"} | {
    s.lower() for s in STATUS_MEMBERS - {"CERTIFIED"}
}
#: The calls that decide: only certificate.py's own factories call them.
DECIDE = {"decide_mu", "decide_gain", "decide_gridded_gain"}
#: What a caller hands its facts to (a function calling one of them derives nothing from words).
FACTORIES = {
    "certify_loop",
    "certificate_of_sweep",
    "rescoped",
    "gain_certificate",
    "gridded_gain_certificate",
    "nominal_performance_verdict",
}


def _name(node) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return ""


def _read_only(tree) -> set[int]:
    """Nodes inside a comparison (``status == Status.CERTIFIED.value`` reads a decided status) or ``__all__``."""
    ids = set()
    for node in ast.walk(tree):
        names = [t.id for t in getattr(node, "targets", []) if isinstance(t, ast.Name)]
        if isinstance(node, ast.Compare) or (isinstance(node, ast.Assign) and "__all__" in names):
            ids |= {id(n) for n in ast.walk(node)} - ({id(node)} if isinstance(node, ast.Assign) else set())
    return ids


def _docstrings(tree) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                ids.add(id(first.value))
    return ids


def decisions_outside(path: Path) -> list[str]:
    """``path:line: what`` for every status or verdict decided in ``path``."""
    tree = ast.parse(path.read_text())
    skip = _docstrings(tree)
    reads = _read_only(tree)
    found = []
    where = path.relative_to(PACKAGE.parent) if path.is_relative_to(PACKAGE.parent) else path.name

    def hit(node, what):
        found.append(f"{where}:{node.lineno}: {what}")

    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr in STATUS_MEMBERS and _name(node.value) == "Status":
            if id(node) not in reads:
                hit(node, f"chooses Status.{node.attr}")
        elif isinstance(node, ast.Call):
            called = _name(node.func)
            if called == "Certificate":
                hit(node, "builds a Certificate")
            elif called in DECIDE:
                hit(node, f"calls {called} (pass the facts to a certificate.py factory)")
            elif called == "replace" and any(k.arg == "status" for k in node.keywords):
                hit(node, "rewrites a status after the decision")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip | reads:
            word = node.value.strip()
            if word in STATUS_MEMBERS or word.lower() in VERDICT_WORDS:
                hit(node, f"spells the verdict {word!r}")
    for fn in ast.walk(tree):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        calls = [n for n in ast.walk(fn) if isinstance(n, ast.Call)]
        if any(_name(c.func) in FACTORIES | DECIDE for c in calls):
            for c in calls:
                if _name(c.func) in {"startswith", "endswith"}:
                    hit(c, f"{fn.name} passes certificate.py facts read from words ({_name(c.func)})")
    return found


def _sources():
    return [p for p in sorted(PACKAGE.rglob("*.py")) if p != DECIDER]


def test_no_status_or_verdict_decided_outside_certificate_module():
    found = [line for path in _sources() for line in decisions_outside(path)]
    assert not found, "decided outside analysis/certificate.py:\n" + "\n".join(found)


@pytest.mark.parametrize(
    "code, what",
    [
        (
            "if s.startswith('on the grid'):\n    x = decide_gridded_gain(True, 0.5, False)\n",
            "calls decide_gridded_gain",
        ),
        ("def f(r):\n    return gridded_gain_certificate(s, between=r.coverage.startswith('on'))\n", "read from words"),
        ("c = replace(c, status=s)\n", "rewrites a status"),
        ("def f(c):\n    return Status.VIOLATED if c.lower >= 1 else c.status\n", "chooses Status.VIOLATED"),
        ("if c.status is Status.CERTIFIED:\n    words = c.verdict\n", None),
        ("__all__ = ['fail', 'pair']\n", None),
        ("w = 'met' if x < 1 else 'not met'\n", "spells the verdict 'met'"),
        ("c = Certificate(s, 1.0, 1.0, 1.0, None, scope)\n", "builds a Certificate"),
        ("def f():\n    '''NOT_CERTIFIED in a docstring is words, not a decision.'''\n", None),
    ],
)
def test_the_checker_sees_each_kind_of_decision(tmp_path, code, what):
    probe = tmp_path / "probe.py"
    probe.write_text(code)
    found = decisions_outside(probe)
    if what is None:
        assert found == []
    else:
        assert any(what in line for line in found), found


def _loop(gain: float):
    """``N = gain/(s + 2)`` as a bare generalized plant: μ of the one complex block is ``gain/2``."""
    import control

    return control.ss([[-1.0]], [[gain, 1.0]], [[1.0], [1.0]], [[0.0, 0.0], [0.0, 0.0]])


def test_a_sufficient_test_is_decided_not_certified_in_the_decision_not_rewritten():
    from polyrob.analysis.certificate import Status, certify_loop

    exact = certify_loop(_loop(3.0), -1.0, [[1, 1]], n_u=1, n_y=1)  # mu = 1.5, lower bound too
    sufficient = certify_loop(_loop(3.0), -1.0, [[1, 1]], n_u=1, n_y=1, lower_bound_disproves=False)
    assert exact.status is Status.VIOLATED
    assert sufficient.status is Status.NOT_CERTIFIED
    assert sufficient.mu_lower == pytest.approx(1.5, rel=3e-3)
    assert sufficient.reasons == (
        f"this test cannot prove it: mu lower bound {sufficient.mu_lower:.4g} >= 1 of the scaled structure "
        "(a sufficient test; no robot of the set is shown to violate it)",
    )


def test_mu_upper_is_the_proved_bound_and_the_grid_peak_has_its_own_name():
    import math
    from dataclasses import replace
    from types import SimpleNamespace as NS

    from polyrob.analysis.certificate import certificate_of_sweep, certify_loop

    c = certify_loop(_loop(1.0), -1.0, [[1, 1]], n_u=1, n_y=1)  # mu = 0.5 at every frequency
    assert c.certified and c.bound_everywhere
    assert c.mu_upper == c.bound and c.mu_upper == pytest.approx(0.5, rel=2e-2)
    assert c.mu_upper_grid == pytest.approx(0.5, rel=2e-3) and c.mu_upper >= c.mu_upper_grid
    # the same sweep with a check between its points that gave up: a grid peak, no proved bound
    gave_up = NS(holds=False, level=math.nan, peak_upper=0.5, failed_at=None, reason="gave up", summary=dict)
    g = certificate_of_sweep(c.closed_loop, replace(c.mu, between=gave_up), stability=c.stable_at_delta0)
    assert g.status.value == "GRID_ONLY" and not g.bound_everywhere
    assert math.isinf(g.mu_upper) and g.mu_upper_grid == c.mu_upper_grid == g.bound


def test_a_model_that_misses_jacobians_certifies_the_model_not_the_robot():
    from dataclasses import replace

    from polyrob.analysis.certificate import Scope, certify_loop, rescoped

    c = certify_loop(_loop(1.0), -1.0, [[1, 1]], n_u=1, n_y=1)
    gap = rescoped(c, replace(Scope(), model="inner-gain", coverage=0.9, coverage_points=200))
    assert c.certified and gap.status.value == "NOT_CERTIFIED"
    assert gap.reasons == ("the 'inner-gain' model contains only 0.9 of 200 fresh Jacobians",)
    assert gap.mu_upper == c.mu_upper  # the bound is proved; what it certifies is the model


def test_nominal_performance_verdict_is_decided_in_the_certificate_module():
    from polyrob.analysis.certificate import nominal_performance_verdict

    assert [nominal_performance_verdict(x) for x in (0.999, 1.0, float("inf"))] == ["met", "not met", "not met"]
