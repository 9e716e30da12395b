"""Output paths checked before the work starts, and one stem for a pair of files.

A command that runs for minutes must not fail at the end because ``-o``
names a directory, a read-only place or a file used as a directory; and
``-o q.npz`` must not write the JSON over the arrays.  Both are decided here,
before any computation, so a refused path leaves nothing behind.

Examples
--------
>>> from polyrob.io.paths import pair_paths
>>> [p.name for p in pair_paths("out/q.npz")]
['q.json', 'q.npz']
>>> [p.name for p in pair_paths("out/q")]
['q.json', 'q.npz']
"""

from __future__ import annotations

import os
from pathlib import Path

from polyrob.errors import ArgumentError

__all__ = ["check_output_path", "pair_paths", "cache_dir"]

#: Suffixes that name one file of a JSON + .npz pair (the stem is what is left).
PAIR_SUFFIXES = (".json", ".npz")
#: Virtual file systems: writable-looking for root, never a place for results.
VIRTUAL_ROOTS = (Path("/proc"), Path("/sys"), Path("/dev"))


def pair_paths(path) -> tuple[Path, Path]:
    """The JSON and ``.npz`` paths of a pair written under ``path``, whatever its suffix.

    ``q``, ``q.json`` and ``q.npz`` all give ``(q.json, q.npz)``; another
    suffix is kept as part of the stem (``q.v2`` gives ``q.v2.json``).
    """
    path = Path(path)
    stem = path.with_suffix("") if path.suffix.lower() in PAIR_SUFFIXES else path
    return stem.with_name(stem.name + ".json"), stem.with_name(stem.name + ".npz")


def _first_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check_output_path(path, option: str = "-o") -> Path:
    """Refuse an output path that cannot be written, before any work is done.

    Parameters
    ----------
    path : str or Path
    option : str
        The option that gave ``path``, named in the error.

    Returns
    -------
    Path
        ``path`` itself (nothing is created).

    Raises
    ------
    ArgumentError
        ``path`` is an existing directory, lies in ``/proc``, ``/sys`` or
        ``/dev``, has a file where a directory is needed, or lies in a place
        this process may not write.
    """
    raw = str(path)
    if not raw.strip():
        raise ArgumentError(f"{option}: empty output path")
    path = Path(raw).expanduser()
    if raw.endswith(os.sep) or path.is_dir():
        raise ArgumentError(f"{option} {raw}: is a directory; give a file name (e.g. {Path(raw) / 'out.json'})")
    resolved = Path(os.path.abspath(path))
    for root in VIRTUAL_ROOTS:
        if resolved == root or root in resolved.parents:
            raise ArgumentError(f"{option} {raw}: {root} is not a place for result files; write elsewhere")
    if path.exists() and not os.access(path, os.W_OK):
        raise ArgumentError(f"{option} {raw}: the file exists and is read-only")
    anchor = _first_existing(resolved.parent)
    if not anchor.is_dir():
        raise ArgumentError(f"{option} {raw}: {anchor} is a file, not a directory")
    if not os.access(anchor, os.W_OK | os.X_OK):
        raise ArgumentError(f"{option} {raw}: cannot write in {anchor} (permission denied)")
    return path


def cache_dir(topic: str) -> Path:
    """Where polyrob keeps work worth keeping between commands (a proof's state): ``<root>/<topic>``.

    ``<root>``: ``$POLYROB_CACHE_DIR``, else ``$XDG_CACHE_HOME/polyrob``, else
    ``~/.cache/polyrob`` (the XDG convention).  Not created here.

    Examples
    --------
    >>> import os
    >>> os.environ["POLYROB_CACHE_DIR"] = "/var/tmp/polyrob-cache"
    >>> str(cache_dir("proofs"))
    '/var/tmp/polyrob-cache/proofs'
    >>> del os.environ["POLYROB_CACHE_DIR"]
    """
    root = os.environ.get("POLYROB_CACHE_DIR")
    if not root:
        xdg = os.environ.get("XDG_CACHE_HOME")
        root = Path(xdg) / "polyrob" if xdg else Path.home() / ".cache" / "polyrob"
    return Path(root) / topic
