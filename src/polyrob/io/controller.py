"""Controller files: a python-control system as JSON (or a MATLAB ``.mat``), with its certificate.

A controller file holds either a state-space realisation or a matrix of
transfer functions (per element, as the paper prints K*)::

    {"format": "polyrob.controller/1", "type": "ss",
     "A": [[...]], "B": [[...]], "C": [[...]], "D": [[...]]}

    {"format": "polyrob.controller/1", "type": "tf",
     "num": [[[b2, b1, b0], ...], ...], "den": [[[a3, a2, a1, a0], ...], ...]}

plus free-form ``"certificate"`` and ``"info"`` mappings and a
``"provenance"`` one (:class:`polyrob.provenance.Provenance`: polyrob's and
the libraries' versions, the command, the date, the URDF's and the problem
inputs' hashes; a file without one, written before it was recorded, reads
the same).  ``info`` holds
what the controller was designed for (robot, domain, weight
hyperparameters, uncertainty model, see
:meth:`polyrob.pipeline.Problem.description`) so that an analysis can
refuse a controller made for another problem.  A hand-written file may omit
``"format"``; another format or a later version is refused.  A MATLAB
``.mat`` file with variables ``A, B, C, D`` (e.g. ``save K.mat A B C D``
after ``[A,B,C,D] = ssdata(K)``) is read as a state-space controller.
Files are written to a temporary file and renamed.

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
import math
from pathlib import Path

import control
import numpy as np

from polyrob.controller import Controller
from polyrob.errors import ControllerFileError
from polyrob.io.atomic import atomic_write, json_default

__all__ = ["save_controller", "load_controller", "load_controller_value", "read_controller_file", "ControllerFileError", "FORMAT"]

FORMAT = "polyrob.controller/1"
_FAMILY, _VERSION = FORMAT.split("/")


def save_controller(
    K, path, *, certificate: dict | None = None, info: dict | None = None, provenance=None
) -> Path:
    """Write ``K`` (StateSpace or TransferFunction), its certificate and its provenance to ``path``.

    Parameters
    ----------
    K : control.StateSpace or control.TransferFunction
    path : str or Path
    certificate : dict, optional
        Peak μ bounds, structure, order, ... (free form, JSON-serialisable).
    info : dict, optional
        What the controller was made for (robot, domain, weights, uncertainty
        model), compared by :func:`polyrob.pipeline.check_controller_problem`.
    provenance : Provenance, optional
        What made it (:meth:`polyrob.provenance.Provenance.capture` with the
        robot, whose URDF is then hashed); default: captured here from
        ``info``, without the robot's files.

    Returns
    -------
    Path
    """
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
    if provenance is None:
        from polyrob.provenance import Provenance

        provenance = Provenance.capture(description=info, function="polyrob.io.controller.save_controller")
    doc = {"format": FORMAT, **data, "certificate": certificate or {}, "info": info or {}}
    doc["provenance"] = provenance.to_dict()
    atomic_write(path, lambda f: f.write(json.dumps(doc, indent=1, default=json_default)))
    return path


def _check_format(path: Path, doc: dict) -> None:
    fmt = doc.get("format")
    if fmt is None:  # hand-written: read as version 1
        return
    family, _, version = str(fmt).partition("/")
    if family != _FAMILY:
        raise ControllerFileError(f"{path}: format {fmt!r} is not a controller file (expected {FORMAT!r})")
    if version != _VERSION:
        raise ControllerFileError(
            f"{path}: controller file version {version!r}; this polyrob reads version {_VERSION} ({FORMAT!r})"
        )


def _read_mat(path: Path) -> dict:
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    try:
        raw = loadmat(str(path))
    except (MatReadError, OSError, ValueError, TypeError, NotImplementedError) as exc:
        raise ControllerFileError(f"{path}: not a MATLAB .mat file scipy can read ({exc})") from None
    missing = [k for k in "ABCD" if k not in raw]
    if missing:
        raise ControllerFileError(
            f"{path}: a .mat controller needs variables A, B, C, D (missing {', '.join(missing)}); "
            f"in MATLAB: [A,B,C,D] = ssdata(K); save K.mat A B C D"
        )
    return {"type": "ss", **{k: np.asarray(raw[k], float).tolist() for k in "ABCD"}, "info": {}, "certificate": {}}


def read_controller_file(path) -> dict:
    """The raw mapping of a controller file (JSON or ``.mat``), with its format checked.

    Raises
    ------
    ControllerFileError
        Missing file, not JSON, no ``type``, another format or version.
    """
    path = Path(path)
    if not path.is_file():
        raise ControllerFileError(f"{path}: no such controller file")
    if path.suffix.lower() == ".mat":
        return _read_mat(path)
    try:
        doc = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise ControllerFileError(f"{path}: not JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise ControllerFileError(f"{path}: a controller file is a JSON object (see polyrob.io.controller)")
    _check_format(path, doc)
    if doc.get("type") not in ("ss", "tf"):
        raise ControllerFileError(f'{path}: a controller file needs "type": "ss" or "tf" (see polyrob.io.controller)')
    for key in ("info", "certificate", "provenance"):
        if not isinstance(doc.get(key, {}), dict):
            raise ControllerFileError(f'{path}: "{key}" must be a JSON object')
    return doc


def _finite(path: Path, name: str, values) -> None:
    """Refuse NaN/inf before a linear-algebra routine turns it into an obscure error."""
    flat = np.asarray(values, float).ravel()
    bad = np.flatnonzero(~np.isfinite(flat))
    if bad.size:
        raise ControllerFileError(
            f"{path}: {name} has {bad.size} non-finite value(s) (NaN or inf); a controller needs finite numbers"
        )


def controller_from_mapping(doc: dict, path="controller"):
    """A ``control.StateSpace``/``TransferFunction`` from the mapping of a controller file."""
    try:
        if doc["type"] == "ss":
            mats = [np.atleast_2d(np.asarray(doc[k], float)) for k in "ABCD"]
            for k, mat in zip("ABCD", mats):
                _finite(path, k, mat)
            if mats[0].size == 0:  # a static gain
                n_out, n_in = mats[3].shape
                mats[0] = np.zeros((0, 0))
                mats[1] = np.zeros((0, n_in))
                mats[2] = np.zeros((n_out, 0))
            return control.ss(*mats)
        num = [[list(map(float, p)) for p in row] for row in doc["num"]]
        den = [[list(map(float, p)) for p in row] for row in doc["den"]]
        for name, rows in (("num", num), ("den", den)):
            _finite(path, name, [c for row in rows for p in row for c in p] or [0.0])
        for i, row in enumerate(den):
            for j, p in enumerate(row):
                if not any(c != 0 for c in p):
                    raise ControllerFileError(f"{path}: den[{i}][{j}] is zero")
        return control.tf(num, den)
    except (KeyError, ValueError, TypeError, IndexError, np.linalg.LinAlgError) as exc:
        raise ControllerFileError(f"{path}: malformed controller ({exc})") from None


def load_controller(path):
    """Read a controller file: a ``control.StateSpace`` or ``control.TransferFunction``.

    Parameters
    ----------
    path : str or Path
        A JSON controller file (``ss`` or ``tf``) or a MATLAB ``.mat`` file
        with ``A, B, C, D``.

    Raises
    ------
    ControllerFileError
        Missing, malformed, non-finite, or of another format/version.
    """
    path = Path(path)
    return controller_from_mapping(read_controller_file(path), path)


def load_controller_value(path) -> Controller:
    """Read a controller file (:func:`load_controller`) as one :class:`~polyrob.controller.Controller`.

    A ``tf`` file is realised exactly (:meth:`Controller.of <polyrob.controller.Controller.of>`);
    the Controller's ``system`` is the file's ``StateSpace`` for an ``ss`` file.

    Raises
    ------
    ControllerFileError
        As :func:`load_controller`.
    """
    return Controller.of(load_controller(path))


def same_number(a, b, rtol: float = 1e-9) -> bool:
    """Two floats from a file and from memory are the same value (JSON round trip)."""
    return math.isclose(float(a), float(b), rel_tol=rtol, abs_tol=1e-12)
