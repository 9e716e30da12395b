"""Shared fixtures: small URDFs that must be refused, and loaded robots."""

from __future__ import annotations

import dataclasses
import fcntl
import functools
import hashlib
import io
import os
import pickle
import signal
from pathlib import Path

import pytest

from polyrob import load_robot
from polyrob.plant.models import inner_links


@functools.cache
def cached_robot(name: str):
    """Robots are immutable: load each once per test session."""
    return load_robot(name)


@functools.cache
def paper_pldi():
    """The paper's problem: ``paper_2r`` on ``--domain paper`` (PLDIs are immutable)."""
    from polyrob import bound_pldi

    return bound_pldi(cached_robot("paper_2r"), samples=256, coverage=0, progress=False)


class _DoctestNamespace:
    """The doctests' shared objects, in pytest's ``doctest_namespace``.

    Registered as a plugin (below), not defined as a fixture of this file: a
    conftest's fixtures reach only the tests under its folder, and the
    doctests are in src/polyrob. It reaches them when tests/ is among the
    paths pytest was given (the default run, CI); ``pytest src/polyrob/x.py``
    alone does not load this file.
    """

    @pytest.fixture(autouse=True)
    def _doctest_objects(self, request, doctest_namespace):
        dtest = getattr(request.node, "dtest", None)  # a doctest item
        if dtest is not None and any("paper_pldi" in ex.source for ex in dtest.examples):
            # ``paper_pldi``: bound_pldi(load_robot("paper_2r"), samples=256, coverage=0, progress=False),
            # built once per session (and per xdist worker) for the doctests that use it
            doctest_namespace["paper_pldi"] = paper_pldi()


def pytest_configure(config):
    config.pluginmanager.register(_DoctestNamespace(), "polyrob-doctest-namespace")


# --------------------------------------------------------------------------- computed once per session

_SESSION_FOLDER: list[Path] = []


@pytest.fixture(autouse=True)
def _own_proof_cache(tmp_path_factory, monkeypatch):
    """Each test its own cache of proofs (``polyrob.io.paths.cache_dir``): a proof another test finished must not
    be taken for this one's work (its progress, its boxes), and nothing is written to the user's home."""
    monkeypatch.setenv("POLYROB_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))


@pytest.fixture(scope="session", autouse=True)
def _session_folder(tmp_path_factory):
    """The session's temporary folder, above every xdist worker's own (where :func:`once` keeps its results)."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    _SESSION_FOLDER[:] = [root]


class _Digest(pickle.Pickler):
    """Pickles what decides a computation: a loop's drawn true robots and a domain's torque cache left out.

    ``_scenarios`` (the true robots an inner loop's *bounds* are sampled at)
    and ``_torques`` (a cache of the domain's torque range) are read by no
    model build; two loops equal but for them build the same model.
    """

    SKIP = ("_scenarios", "_torques")

    def reducer_override(self, obj):
        if dataclasses.is_dataclass(obj) and not isinstance(obj, type) and any(hasattr(obj, k) for k in self.SKIP):
            state = {k: v for k, v in vars(obj).items() if k not in self.SKIP}
            return tuple, ((type(obj).__module__, type(obj).__qualname__, state),)
        return NotImplemented


def digest(*objects) -> str:
    buffer = io.BytesIO()
    _Digest(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(objects)
    return hashlib.sha256(buffer.getvalue()).hexdigest()[:32]


def once(tag: str, make, *inputs):
    """``make()``, computed once per test session (also across xdist workers) for equal ``inputs``.

    The result (or the exception ``make`` raised) is pickled in the session's
    folder under ``tag`` and the digest of ``inputs`` (:func:`digest`: they
    must hold everything ``make`` reads); a worker that needs a result another
    is computing waits for it (a lock file), as tests/test_cli_synth.py's
    ``shared`` does for its CLI runs.  Deterministic computations only.
    """
    folder = _SESSION_FOLDER[0] / "once"
    folder.mkdir(exist_ok=True)
    path = folder / f"{tag}-{digest(*inputs)}.pickle"
    with open(path.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not path.exists():
            try:
                outcome = ("value", make())
            except Exception as exc:
                outcome = ("raised", exc)
            path.write_bytes(pickle.dumps(outcome))
        else:
            outcome = pickle.loads(path.read_bytes())
    if outcome[0] == "raised":
        raise outcome[1]
    return outcome[1]


def light_model_once(loop, domain, *, samples: int = 64):
    """:func:`polyrob.plant.models.inner_links.light_model` (what ``carried`` measures on), once per session.

    For the unpatched model only: called while a test has patched the model's
    functions, it would keep (or give) a result of other code.
    """
    return once("light_model", lambda: _LIGHT_MODEL(loop, domain, samples=samples), loop, domain, samples)


_LIGHT_MODEL = inner_links.light_model  # the module's own, whatever a test patches


@pytest.fixture
def light_models_once(monkeypatch):
    """``inner_links.light_model`` as :func:`light_model_once` for this test: a set measured by another test
    (or by an earlier command of this one) on an equal loop and domain is not measured again.

    ``carried`` and the CLI's refusals look it up in the module at each call, so they go through it.
    """
    monkeypatch.setattr(inner_links, "light_model", light_model_once)


@pytest.fixture(scope="session")
def pldi():
    """The paper's problem as a PLDI (shared by the plant and uncertainty tests)."""
    return paper_pldi()


@pytest.fixture(scope="session")
def unc(pldi):
    from polyrob.plant.uncertainty import uncertain_plant

    return uncertain_plant(pldi, model="box")


LINK = '<link name="{n}"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>'
JOINT = (
    '<joint name="{n}" type="{t}"><parent link="{p}"/><child link="{c}"/><axis xyz="0 0 1"/>'
    '<limit lower="-1" upper="1" velocity="1" effort="1"/></joint>'
)


def urdf_text(links, joints) -> str:
    body = "".join(LINK.format(n=n) for n in links)
    body += "".join(JOINT.format(n=n, t=t, p=p, c=c) for n, t, p, c in joints)
    return f'<?xml version="1.0"?><robot name="test">{body}</robot>'


@pytest.fixture
def write_urdf(tmp_path):
    def write(text: str, name: str = "robot.urdf"):
        path = tmp_path / name
        path.write_text(text)
        return path

    return write


BAD_URDFS = {
    "malformed": '<?xml version="1.0"?><robot name="x"><link name="a"/><joint name="j" type="revolute">',
    "floating": urdf_text(["base", "body"], [("free", "floating", "base", "body")]),
    "tree": urdf_text(["base", "l1", "l2"], [("j1", "revolute", "base", "l1"), ("j2", "revolute", "base", "l2")]),
    "no_joint": urdf_text(["base", "l1"], [("j1", "fixed", "base", "l1")]),
    "not_urdf": '<?xml version="1.0"?><sdf version="1.6"/>',
}


def default_sigint() -> None:
    """A ``preexec_fn`` giving a child Ctrl-C back: a child of a shell without job control (CI) starts
    with SIGINT ignored, and Python then installs no KeyboardInterrupt handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def child_pids(pid: int) -> list[int]:
    """The direct children of a process (Linux /proc), [] when it is gone."""
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(x) for x in f.read().split()]
    except OSError:
        return []


def describe_processes(pid: int) -> str:
    """State and kernel wait channel of a process and its children (what a hang looks like)."""
    rows = []
    for p in [pid, *sorted(child_pids(pid))]:
        try:
            state = open(f"/proc/{p}/stat").read().split(")")[-1].split()[0]
            wchan = open(f"/proc/{p}/wchan").read()
            cmd = open(f"/proc/{p}/cmdline").read().replace("\0", " ")[:80]
        except OSError:
            rows.append(f"{p}: gone")
            continue
        rows.append(f"{p}: state {state}, waiting in {wchan or '-'}: {cmd}")
    return "; ".join(rows)


def process_running(pid: int) -> bool:
    """The OS's view (Linux /proc): the process exists and is not a zombie.

    ``multiprocessing.Process.is_alive`` can say True for a child that
    another thread of the parent has just reaped (``Popen.poll`` is not
    thread-safe); /proc cannot.
    """
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False
