"""Where a result comes from: polyrob's version, the libraries, the command, the machine, the date and the inputs' hashes.

Every file polyrob writes for a user to keep (a controller file, a PLDI file,
a run's ``certificate.json`` and its report) carries a ``"provenance"``
mapping, :meth:`Provenance.to_dict` of a :class:`Provenance` that
:meth:`Provenance.capture` made when the file was written:

* ``polyrob_version`` (and ``source_commit``, ``git describe`` of a source
  checkout, ``None`` for an installed package), ``dependencies`` (pin,
  example-robot-data, numpy, scipy, control, slycot, cvxpy) and ``solvers``
  (the cvxpy solvers polyrob asks for: Clarabel, then SCS), as installed;
* ``command``: ``polyrob ARGS`` as typed when the ``polyrob`` command wrote
  the file, else ``library call: FUNCTION``;
* ``platform``, ``machine``, ``python`` and ``created_utc`` (ISO 8601);
* ``urdf_sha256`` / ``srdf_sha256``: SHA-256 of the robot's URDF (and SRDF)
  file bytes, ``None`` for an analytic model;
* ``inputs`` and ``inputs_sha256``: the options that define the problem
  (the domain's bounds, the weights, the uncertainty model asked for, the
  reflected inertia and the inner layer; names of domains left out, see
  :func:`problem_inputs`) and the SHA-256 of their canonical JSON
  (:func:`canonical_json`);
* ``input_files``: the SHA-256 of each file the command read its problem
  from (``--domain``, ``--robot-uncertainty``, ``--pldi`` and its arrays,
  ``--init``, a batch's ``--jobs``).

``polyrob export`` records the export's provenance and the controller
file's SHA-256 and provenance beside the C code.

:func:`differences` says, one line per difference, how the robot and the
problem of a file differ from the ones it is used with (``polyrob analyze``
prints them).  A file written before provenance was recorded has none:
:meth:`Provenance.of_file` gives ``None`` and nothing is compared.

Examples
--------
>>> import datetime
>>> when = datetime.datetime(2026, 11, 28, tzinfo=datetime.timezone.utc)
>>> p = Provenance.capture(description={"weights": {"omega_b": [1.0]}}, function="example", now=when)
>>> p.command, p.created_utc, p.inputs_sha256 == sha256_text(canonical_json(p.inputs))
('library call: example', '2026-11-28T00:00:00+00:00', True)
>>> Provenance.from_dict(p.to_dict()) == p
True
>>> q = Provenance.capture(description={"weights": {"omega_b": [2.0]}}, function="example", now=when)
>>> differences(p, q)  # doctest: +ELLIPSIS
['problem inputs differ from those the file was made for (weights omega_b): sha256 ... given, ... recorded']
"""

from __future__ import annotations

import contextlib
import contextvars
import datetime
import functools
import hashlib
import json
import math
import os
import platform
import shlex
import subprocess
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

__all__ = [
    "Provenance",
    "DEPENDENCIES",
    "SOLVERS",
    "canonical_json",
    "sha256_file",
    "sha256_text",
    "source_digest",
    "problem_inputs",
    "differences",
    "command_line",
    "robot_urdf",
]

#: Distributions whose versions a result records (the PyPI names).
DEPENDENCIES = ("pin", "example-robot-data", "numpy", "scipy", "control", "slycot", "cvxpy")
#: The cvxpy solvers polyrob asks for: Clarabel, SCS where Clarabel fails (their distributions).
SOLVERS = ("clarabel", "scs")
#: Keys of a domain that name it rather than bound it (a file's path, an SRDF pose's name): not hashed.
NAMING_KEYS = ("name", "pose_source")
#: Options that may name a file a problem is read from (argparse keeps each as ``args.robot_uncertainty``, ...).
INPUT_FILE_OPTIONS = ("--domain", "--robot-uncertainty", "--pldi", "--init", "--jobs")
#: Hex digits of a hash shown in a sentence (the files hold all 64).
SHORT = 12

# what the running ``polyrob`` command is: (its command line, {label: {"path", "sha256"}}), or None
_INVOCATION: contextvars.ContextVar = contextvars.ContextVar("polyrob_invocation", default=None)


# --------------------------------------------------------------------------- hashing


def _plain(x):
    """JSON values of ``x``: arrays as lists, numpy scalars as Python ones, ``-0.0`` as ``0.0``."""
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if hasattr(x, "tolist"):  # numpy arrays and scalars
        return _plain(x.tolist())
    if isinstance(x, bool) or x is None or isinstance(x, (int, str)):
        return x
    if isinstance(x, float):
        return x + 0.0 if math.isfinite(x) else str(x)  # -0.0 and 0.0 are one input; NaN has no JSON
    return str(x)


def canonical_json(obj) -> str:
    """One text per value: sorted keys, no spaces, floats as Python's shortest repr (hash input).

    >>> canonical_json({"b": [1.0, -0.0], "a": (2,)})
    '{"a":[2],"b":[1.0,0.0]}'
    """
    return json.dumps(_plain(obj), sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def sha256_text(text: str) -> str:
    """SHA-256 (hex) of ``text`` in UTF-8."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def sha256_file(path) -> str:
    """SHA-256 (hex) of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@functools.cache
def source_digest(root) -> str:
    """SHA-256 (hex) of the ``*.py`` files under ``root`` (a folder of polyrob's source), names and bytes.

    What a kept result (a proof's checkpoint, a task cell's certificate) is
    keyed on, so that changed code never reuses it.

    >>> import polyrob
    >>> from pathlib import Path
    >>> len(source_digest(Path(polyrob.__file__).parent / "bounds"))
    64
    """
    root = Path(root).resolve()
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def problem_inputs(description: Mapping | None, robot=None) -> dict:
    """The options that define a problem, from a :meth:`~polyrob.pipeline.Problem.description` (or part of it).

    The domain's bounds (not its name: the same bounds from a file or from
    options are one problem), the weights, the uncertainty model asked for
    and whether symmetric entries are merged, the reflected inertia and the
    inner layer (from ``robot`` when the description lacks them).  Keys
    missing from both are left out.
    """
    d = dict(description or {})
    out = {}
    if isinstance(d.get("domain"), Mapping):
        out["domain"] = {k: v for k, v in d["domain"].items() if k not in NAMING_KEYS}
    if isinstance(d.get("weights"), Mapping):
        out["weights"] = dict(d["weights"])
    if isinstance(d.get("uncertainty"), Mapping):
        out["uncertainty"] = {k: d["uncertainty"][k] for k in ("requested", "merge_symmetric") if k in d["uncertainty"]}
    if "reflected_inertia" in d or robot is not None:  # worded as Problem.description words it
        out["reflected_inertia"] = str(d.get("reflected_inertia", getattr(robot, "reflected_inertia", "unknown")))
    if "inner" in d or hasattr(robot, "inner"):  # an inner loop's words
        out["inner"] = str(d["inner"]) if "inner" in d else robot.words()
    return _plain(out)


# --------------------------------------------------------------------------- the environment


@functools.lru_cache(maxsize=1)
def _environment() -> dict:
    """What does not change while a process runs: versions, the source checkout, the machine."""
    import importlib.metadata

    def version(name):
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            return "not installed"

    from polyrob import __version__

    return {
        "polyrob_version": __version__,
        "source_commit": _source_commit(),
        "dependencies": {name: version(name) for name in DEPENDENCIES},
        "solvers": {name: version(name) for name in SOLVERS},
        "platform": platform.platform(),
        "machine": platform.machine(),
        "python": platform.python_version(),
    }


def _source_commit() -> str | None:
    """``git describe --always --dirty`` of the checkout polyrob runs from; ``None`` for an installed package."""
    here = Path(__file__).resolve().parent
    if not any((p / ".git").exists() for p in (here, *here.parents)):
        return None
    try:
        done = subprocess.run(
            ["git", "-C", str(here), "describe", "--always", "--dirty", "--abbrev=12"],
            capture_output=True,
            text=True,
            timeout=30,  # a safety net: the commit is recorded when git answers, nothing waits on it
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    described = done.stdout.strip() if done.returncode == 0 else ""
    return described or None


def _robot_files(robot) -> tuple[str | None, str | None]:
    """The URDF and SRDF paths of ``robot`` (an inner loop's are its true robot's); ``None``: none."""
    base = getattr(robot, "true_robot", robot)
    source = getattr(base, "source", None)
    srdf = getattr(base, "srdf", None)
    return _file_path(source), _file_path(srdf)


def _file_path(path) -> str | None:
    """``path`` made absolute when it names a file (a robot's ``source`` may be a description)."""
    return os.path.abspath(path) if path and Path(str(path)).is_file() else None


def robot_urdf(robot) -> str | None:
    """The URDF file a robot name or path names (as :func:`polyrob.load_robot` finds it); ``None``: none.

    An analytic model, an unknown name or nothing given has none.
    """
    if not robot:
        return None
    from polyrob.errors import RobotError
    from polyrob.model.robots import resolve_urdf

    try:
        return _file_path(resolve_urdf(str(robot)))
    except RobotError:
        return None


def files_of_args(args) -> dict:
    """``{option: {"path", "sha256"}}`` of the files :data:`INPUT_FILE_OPTIONS` name (``--pldi``: both halves).

    A value that is not a file (a named domain, ``--init pid``) is no file input.
    """
    out = {}
    for option in INPUT_FILE_OPTIONS:
        value = getattr(args, option.lstrip("-").replace("-", "_"), None)
        if not value:
            continue
        paths = [Path(value)]
        if option == "--pldi":
            from polyrob.io.paths import pair_paths

            paths = list(pair_paths(value))
        for k, path in enumerate(paths):
            if path.is_file():
                label = option if k == 0 else f"{option} arrays"
                out[label] = {"path": os.path.abspath(path), "sha256": sha256_file(path)}
    return out


@contextlib.contextmanager
def command_line(argv, args=None):
    """While the ``polyrob`` command runs: what :meth:`Provenance.capture` records as its command and input files.

    ``argv`` are the command's arguments (``sys.argv[1:]``); ``args`` its
    parsed options, whose input files are hashed now, as the command reads them.
    """
    token = _INVOCATION.set(("polyrob " + shlex.join(str(a) for a in argv), files_of_args(args) if args else {}))
    try:
        yield
    finally:
        _INVOCATION.reset(token)


# --------------------------------------------------------------------------- the record


@dataclass(frozen=True)
class Provenance:
    """What made a result: see the module text for each field.

    Build it with :meth:`capture`; read it back with :meth:`from_dict` or
    :meth:`of_file`.
    """

    polyrob_version: str = "unknown"
    source_commit: str | None = None
    dependencies: dict = field(default_factory=dict)
    solvers: dict = field(default_factory=dict)
    command: str = "unknown"
    platform: str = "unknown"
    machine: str = "unknown"
    python: str = "unknown"
    created_utc: str = "unknown"
    robot: str | None = None
    urdf: str | None = None
    urdf_sha256: str | None = None
    srdf: str | None = None
    srdf_sha256: str | None = None
    inputs: dict = field(default_factory=dict)
    inputs_sha256: str | None = None
    input_files: dict = field(default_factory=dict)

    @classmethod
    def capture(
        cls,
        *,
        robot=None,
        urdf=None,
        description: Mapping | None = None,
        function: str | None = None,
        command: str | None = None,
        now: datetime.datetime | None = None,
    ) -> Provenance:
        """The provenance of a result made now, in this process.

        Parameters
        ----------
        robot : Manipulator, optional
            Its URDF and SRDF are hashed (an analytic model has neither).
        urdf : path, optional
            A URDF to hash when no ``robot`` is at hand (a PLDI file's source).
        description : mapping, optional
            The problem (:meth:`~polyrob.pipeline.Problem.description`, or
            part of it); its options are hashed (:func:`problem_inputs`).
        function : str, optional
            The library function writing the result: the command is
            ``library call: FUNCTION`` outside the ``polyrob`` command.
        command : str, optional
            The command line, instead of the running command's.
        now : datetime, optional
            The time recorded (default: the clock, in UTC).
        """
        invocation = _INVOCATION.get()
        if command is None:
            command = invocation[0] if invocation else f"library call: {function or 'polyrob'}"
        urdf_path, srdf_path = _robot_files(robot) if robot is not None else (None, None)
        urdf_path = urdf_path or _file_path(urdf)
        inputs = problem_inputs(description, robot)
        name = getattr(robot, "name", None) or (description or {}).get("robot")
        when = now or datetime.datetime.now(datetime.timezone.utc)
        return cls(
            **_environment(),
            command=command,
            created_utc=when.astimezone(datetime.timezone.utc).isoformat(timespec="seconds"),
            robot=None if name is None else str(name),
            urdf=urdf_path,
            urdf_sha256=None if urdf_path is None else sha256_file(urdf_path),
            srdf=srdf_path,
            srdf_sha256=None if srdf_path is None else sha256_file(srdf_path),
            inputs=inputs,
            inputs_sha256=sha256_text(canonical_json(inputs)) if inputs else None,
            input_files=dict(invocation[1]) if invocation else {},
        )

    def to_dict(self) -> dict:
        """Plain JSON values (what a file stores under ``"provenance"``)."""
        return _plain(asdict(self))

    @classmethod
    def from_dict(cls, data: Mapping) -> Provenance:
        """The provenance :meth:`to_dict` wrote; unknown keys are ignored, missing ones left at their defaults."""
        known = {f.name: f for f in fields(cls)}
        values = {}
        for key, value in dict(data).items():
            if key not in known:
                continue
            wants_dict = known[key].default_factory is dict
            if wants_dict and isinstance(value, Mapping):
                values[key] = _plain(value)
            elif not wants_dict and (value is None or isinstance(value, str)):
                values[key] = value
        return cls(**values)

    @classmethod
    def of_file(cls, path) -> Provenance | None:
        """The provenance a JSON file records (a controller file, ``certificate.json``); ``None``: none recorded."""
        path = Path(path)
        if path.suffix.lower() != ".json" or not path.is_file():
            return None
        try:
            doc = json.loads(path.read_text())
        except (OSError, ValueError, UnicodeDecodeError):
            return None
        data = doc.get("provenance") if isinstance(doc, dict) else None
        return cls.from_dict(data) if isinstance(data, Mapping) else None

    def footer(self) -> str:
        """One line: version, command, date and the robot's and inputs' hashes (a report's footer)."""
        parts = [f"polyrob {self.polyrob_version}" + (f" ({self.source_commit})" if self.source_commit else "")]
        parts += [self.command, self.created_utc]
        if self.urdf_sha256:
            parts.append(f"URDF sha256 {self.urdf_sha256[:SHORT]}")
        if self.inputs_sha256:
            parts.append(f"inputs sha256 {self.inputs_sha256[:SHORT]}")
        return " · ".join(parts)


# --------------------------------------------------------------------------- comparing


def _short(h: str | None) -> str:
    return "none" if h is None else h[:SHORT]


def _differing(a, b, prefix: str = "") -> list[str]:
    """Paths of the keys whose values differ (a domain: ``domain qdot``), at most two levels deep."""
    if isinstance(a, Mapping) and isinstance(b, Mapping) and prefix.count(" ") < 1:
        out = []
        for key in sorted(set(a) | set(b)):
            if canonical_json(a.get(key)) != canonical_json(b.get(key)):
                out += _differing(a.get(key), b.get(key), f"{prefix} {key}".strip())
        return out
    return [prefix]


def _file_line(what: str, stored_hash, stored_path, given_hash, given_path) -> str | None:
    if stored_hash == given_hash:
        return None
    given = f"sha256 {_short(given_hash)} ({given_path})" if given_hash else "none"
    recorded = f"sha256 {_short(stored_hash)} ({stored_path})" if stored_hash else "none"
    return f"{what} differs from the one the file was made for: {given} given, {recorded} recorded"


def differences(stored: Provenance, current: Provenance) -> list[str]:
    """One line per way ``current``'s robot or problem differs from ``stored``'s (empty: the same).

    Compared: the robot's name, its URDF and SRDF hashes, the problem inputs'
    hash (naming the inputs that differ, compared on the inputs both record)
    and the hash of each input file both name.  A hash one side does not
    record (a file from before provenance, an analytic robot's URDF) is not
    compared.
    """
    lines = []
    if stored.robot and current.robot and stored.robot != current.robot:
        lines.append(f"robot '{current.robot}' given, the file was made for '{stored.robot}'")
    if stored.urdf_sha256 and current.urdf_sha256:  # two URDF robots (an analytic one differs by its name)
        lines.append(_file_line("URDF", stored.urdf_sha256, stored.urdf, current.urdf_sha256, current.urdf))
        # the SRDF beside each URDF: its rotors and poses are part of the robot
        lines.append(_file_line("SRDF", stored.srdf_sha256, stored.srdf, current.srdf_sha256, current.srdf))
    common = sorted(set(stored.inputs) & set(current.inputs))
    if stored.inputs_sha256 and current.inputs_sha256:
        which = [p for k in common for p in _differing({k: stored.inputs[k]}, {k: current.inputs[k]})]
        whole_differs = stored.inputs_sha256 != current.inputs_sha256
        if which or (whole_differs and set(stored.inputs) == set(current.inputs)):
            named = f" ({', '.join(which)})" if which else ""
            lines.append(
                f"problem inputs differ from those the file was made for{named}: sha256 {_short(current.inputs_sha256)} given, "
                f"{_short(stored.inputs_sha256)} recorded"
            )
    for label in sorted(set(stored.input_files) & set(current.input_files)):
        a, b = stored.input_files[label], current.input_files[label]
        lines.append(_file_line(f"{label} file", a.get("sha256"), a.get("path"), b.get("sha256"), b.get("path")))
    return [line for line in lines if line]
