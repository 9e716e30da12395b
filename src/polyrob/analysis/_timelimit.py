"""A persistent worker process with a time limit per call.

SLICOT AB13MD warm-started from the previous frequency's scalings can hang
(seen at the 52nd point of a sweep); a C routine stuck in a loop cannot be
interrupted from Python, so such calls run in a worker that is killed after
the limit.  :func:`polyrob.analysis.mu.mu_bounds` uses it for ``warm_start=True``.
"""

from __future__ import annotations

import sys as _sys
from typing import Any, Callable

# The worker is plain stdlib code run by ``python -c``: it imports nothing of
# polyrob (whose package import is heavy) unless unpickling ``fn`` needs it.
# Pickles come in on stdin and go out on a private duplicate of fd 1, while
# fd 1 itself is pointed at stderr so stray prints cannot corrupt the channel.
_BOOT = """
import os, pickle, sys
out = os.fdopen(os.dup(1), "wb"); os.dup2(2, 1)
inp = sys.stdin.buffer
sys.path[:] = pickle.load(inp)
fn = pickle.load(inp)
pickle.dump(("ready", None), out); out.flush()
while True:
    try:
        args = pickle.load(inp)
    except EOFError:
        break
    try:
        msg = ("ok", fn(*args))
    except Exception as exc:
        msg = ("err", repr(exc))
    pickle.dump(msg, out); out.flush()
"""


class TimeLimitedCall:
    """Call ``fn`` in a persistent worker process with a time limit.

    AB13MD warm starts (``x`` from the previous frequency) are known to hang
    forever on some inputs, and a Fortran loop cannot be interrupted from
    Python, so the call runs in a child process that is killed on timeout.
    The child is a fresh interpreter (``python -c``), not a fork (forking a
    process whose BLAS threads hold locks can deadlock) nor a
    ``multiprocessing`` spawn (which re-imports the user's ``__main__``
    script); ``fn`` must therefore be picklable, e.g. a module-level function.

    Parameters
    ----------
    fn : callable
        Function to call.
    timeout : float
        Seconds to wait for each call (the worker's start-up is not counted).
    startup_timeout : float
        Seconds to wait for a new worker to import its modules.

    Examples
    --------
    >>> from polyrob.analysis.mu import TimeLimitedCall
    >>> with TimeLimitedCall(abs, timeout=5.0) as call:
    ...     call(-3)
    (True, 3)
    """

    def __init__(self, fn: Callable[..., Any], timeout: float = 2.0, startup_timeout: float = 120.0):
        self.fn, self.timeout, self.startup_timeout = fn, float(timeout), float(startup_timeout)
        self._proc = self._queue = None

    def _start(self) -> bool:
        import pickle
        import queue
        import subprocess
        import threading

        self._proc = subprocess.Popen(
            [_sys.executable, "-c", _BOOT], stdin=subprocess.PIPE, stdout=subprocess.PIPE
        )
        self._queue = q = queue.Queue()
        stdout = self._proc.stdout

        def reader():  # a thread makes the wait portable (no select on pipes)
            while True:
                try:
                    q.put(pickle.load(stdout))
                except Exception:  # noqa: BLE001 - EOF or garbage: worker is gone
                    q.put(("dead", None))
                    return

        threading.Thread(target=reader, daemon=True).start()
        try:
            pickle.dump(list(_sys.path), self._proc.stdin)
            pickle.dump(self.fn, self._proc.stdin)
            self._proc.stdin.flush()
            if q.get(timeout=self.startup_timeout)[0] == "ready":
                return True
        except Exception:  # noqa: BLE001 - unpicklable fn, broken pipe, timeout
            pass
        self.close()
        return False

    def __call__(self, *args) -> tuple[bool, Any]:
        """Return ``(True, value)``, or ``(False, reason)`` on timeout/error."""
        import pickle
        import queue

        if (self._proc is None or self._proc.poll() is not None) and not self._start():
            return False, "worker did not start"
        try:
            pickle.dump(args, self._proc.stdin)
            self._proc.stdin.flush()
            status, value = self._queue.get(timeout=self.timeout)
        except queue.Empty:
            self.close()  # hung: kill the worker, a fresh one starts next call
            return False, "timeout"
        except Exception as exc:  # noqa: BLE001 - broken pipe: worker died
            self.close()
            return False, f"worker failed: {exc!r}"
        if status == "ok":
            return True, value
        if status == "dead":
            self.close()
            return False, "worker died"
        return False, value

    def close(self):
        """Kill the worker (a new one starts on the next call)."""
        if self._proc is not None:
            if self._proc.poll() is None:
                self._proc.kill()
            try:
                self._proc.wait(timeout=5)
            except Exception:  # noqa: BLE001
                pass
            for f in (self._proc.stdin, self._proc.stdout):
                try:
                    f.close()
                except Exception:  # noqa: BLE001
                    pass
        self._proc = self._queue = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass
