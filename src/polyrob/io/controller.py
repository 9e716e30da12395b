"""Controller files: a python-control system as JSON, with an optional certificate.

A controller file holds either a state-space realisation or a matrix of
transfer functions (per element, as the paper prints K*)::

    {"format": "polyrob.controller/1", "type": "ss",
     "A": [[...]], "B": [[...]], "C": [[...]], "D": [[...]]}

    {"format": "polyrob.controller/1", "type": "tf",
     "num": [[[b2, b1, b0], ...], ...], "den": [[[a3, a2, a1, a0], ...], ...]}

plus free-form ``"certificate"`` and ``"info"`` mappings (peak μ, scalings,
order, how it was made).  Files are written to a temporary file and renamed.

Examples
--------
>>> import control, tempfile, pathlib
>>> K = control.tf([[[1.0, 2.0]]], [[[1.0, 10.0]]])
>>> path = pathlib.Path(tempfile.mkdtemp()) / "K.json"
>>> _ = save_controller(K, path, info={"structure": "tf1"})
>>> back = load_controller(path)
>>> round(float(abs(back(1j))), 6) == round(float(abs(K(1j))), 6)
True
"""

from __future__ import annotations

import json
from pathlib import Path

import control
import numpy as np

from polyrob.errors import PolyrobError
from polyrob.io.atomic import atomic_write, json_default

__all__ = ["save_controller", "load_controller", "read_controller_file", "ControllerFileError"]

FORMAT = "polyrob.controller/1"


class ControllerFileError(PolyrobError):
    """A controller file is missing or malformed."""


def save_controller(K, path, *, certificate: dict | None = None, info: dict | None = None) -> Path:
    """Write ``K`` (StateSpace or TransferFunction) and its certificate to ``path``."""
    path = Path(path)
    if isinstance(K, control.TransferFunction):
        data = {
            "type": "tf",
            "num": [[np.asarray(K.num[i][j], float).tolist() for j in range(K.ninputs)] for i in range(K.noutputs)],
            "den": [[np.asarray(K.den[i][j], float).tolist() for j in range(K.ninputs)] for i in range(K.noutputs)],
        }
    else:
        K = control.ss(K)
        data = {"type": "ss", **{k: np.asarray(getattr(K, k), float).tolist() for k in "ABCD"}}
    doc = {"format": FORMAT, **data, "certificate": certificate or {}, "info": info or {}}
    atomic_write(path, lambda f: f.write(json.dumps(doc, indent=1, default=json_default)))
    return path


def read_controller_file(path) -> dict:
    """The raw mapping of a controller file, validated."""
    path = Path(path)
    if not path.is_file():
        raise ControllerFileError(f"{path}: no such controller file")
    try:
        doc = json.loads(path.read_text())
    except ValueError as exc:
        raise ControllerFileError(f"{path}: not JSON ({exc})") from None
    if not isinstance(doc, dict) or doc.get("type") not in ("ss", "tf"):
        raise ControllerFileError(f"{path}: a controller file needs \"type\": \"ss\" or \"tf\" (see polyrob.io.controller)")
    return doc


def load_controller(path):
    """Read a controller file: a ``control.StateSpace`` or ``control.TransferFunction``."""
    doc = read_controller_file(path)
    try:
        if doc["type"] == "ss":
            mats = [np.atleast_2d(np.asarray(doc[k], float)) for k in "ABCD"]
            if mats[0].size == 0:  # a static gain
                n_out, n_in = mats[3].shape
                mats[0] = np.zeros((0, 0))
                mats[1] = np.zeros((0, n_in))
                mats[2] = np.zeros((n_out, 0))
            return control.ss(*mats)
        num = [[list(map(float, p)) for p in row] for row in doc["num"]]
        den = [[list(map(float, p)) for p in row] for row in doc["den"]]
        return control.tf(num, den)
    except (KeyError, ValueError, TypeError) as exc:
        raise ControllerFileError(f"{path}: malformed controller ({exc})") from None
