"""One error class per kind: no bare ``PolyrobError`` where a subclass of :mod:`polyrob.errors` fits.

A bad argument is an :class:`~polyrob.errors.ArgumentError` (also a
``ValueError``, as python-control's) wherever it is raised; the CLI prints
every such error as one line and exits 2.
"""

from __future__ import annotations

import ast
from pathlib import Path

import control
import numpy as np
import pytest

from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.cli import main
from polyrob.errors import ArgumentError
from polyrob.plant.lftplant import upper_lft
from polyrob.plant.weights import makeweight
from polyrob.validate.export_c import c_sources

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "polyrob"


def _message_start(call: ast.Call) -> str:
    arg = call.args[0] if call.args else None
    if isinstance(arg, ast.JoinedStr):
        arg = arg.values[0] if arg.values else None
    return arg.value if isinstance(arg, ast.Constant) and isinstance(arg.value, str) else ""


def bare_raises(source: str, where: str) -> list[str]:
    """``where:line: message`` of each ``raise PolyrobError(...)`` in ``source`` that is not an internal error."""
    found = []
    for node in ast.walk(ast.parse(source)):
        exc = node.exc if isinstance(node, ast.Raise) else None
        if isinstance(exc, ast.Call) and isinstance(exc.func, ast.Name) and exc.func.id == "PolyrobError":
            start = _message_start(exc)
            if not start.startswith("internal error"):  # a bug of polyrob, no user-facing kind
                found.append(f"{where}:{node.lineno}: {start[:60]!r}")
    return found


def test_no_bare_base_class_raised_where_a_subclass_fits():
    found = [
        line
        for path in sorted(PACKAGE.rglob("*.py"))
        for line in bare_raises(path.read_text(), str(path.relative_to(PACKAGE.parent)))
    ]
    assert not found, "raise the subclass of polyrob.errors that fits:\n" + "\n".join(found)


def test_the_checker_sees_a_bare_raise_and_lets_an_internal_error_pass():
    code = 'raise PolyrobError(f"order must be >= 0, got {n}")\nraise PolyrobError("internal error: x")\n'
    code += 'raise ArgumentError("order must be >= 0")\n'
    assert bare_raises(code, "probe.py") == ["probe.py:1: 'order must be >= 0, got '"]


@pytest.mark.parametrize(
    "call",
    [
        (makeweight, (0.1, 1.0, 10.0), {"order": 0}, "order must be a positive integer, got 0"),
        (as_block_structure, ([[0, 1]],), {}, "block 0: [0, 1] has zero size"),
        (c_sources, (None,), {"real": "long"}, "real must be 'double' or 'float', got 'long'"),
        (upper_lft, (control.ss(-1, 1, 1, 0), np.ones((2, 2))), {}, "Δ is 2x2 but M has only 1 inputs and 1 outputs"),
    ],
)
def test_bad_arguments_are_argument_errors_and_value_errors(call):
    function, args, kwargs, message = call
    with pytest.raises(ArgumentError) as info:  # before: a bare PolyrobError, not a ValueError
        function(*args, **kwargs)
    assert isinstance(info.value, ValueError) and str(info.value) == message


def test_cli_prints_an_argument_error_as_one_line_and_exits_2(tmp_path, capsys):
    missing = tmp_path / "no-run-here"
    assert main(["report", str(missing)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"polyrob: error: {missing}: no such run directory"]
