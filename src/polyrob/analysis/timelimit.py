"""A persistent worker process with a time limit per call.

SLICOT AB13MD warm-started from the previous frequency's scalings can hang
(seen at the 52nd point of a sweep); a C routine stuck in a loop cannot be
interrupted from Python, so such calls run in a worker that is killed after
the limit.  :func:`polyrob.analysis.mu.bounds.mu_bounds` uses it for
``warm_start=True`` and for cold calls on structures with real blocks.

The limit is a safety net against a call that never returns, not a way to
choose between algorithms: it measures wall clock, so whether it fires
depends on the machine's load.  Callers set it far above the slowest call
they expect and report in their results when it fired.
"""

from __future__ import annotations

import sys as _sys
from collections.abc import Callable
from typing import Any

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
    >>> from polyrob.analysis.timelimit import TimeLimitedCall
    >>> with TimeLimitedCall(abs, timeout=5.0) as call:
    ...     call(-3)
    (True, 3)
    """

    def __init__(self, fn: Callable[..., Any], timeout: float = 2.0, startup_timeout: float = 120.0):
        self.fn, self.timeout, self.startup_timeout = fn, float(timeout), float(startup_timeout)
        self._proc = self._queue = None
        self.start_error = None

    def _start(self) -> bool:
        import pickle
        import queue
        import subprocess
        import threading

        self._proc = subprocess.Popen([_sys.executable, "-c", _BOOT], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        self._queue = q = queue.Queue()
        stdout = self._proc.stdout

        def reader():  # a thread makes the wait portable (no select on pipes)
            while True:
                try:
                    q.put(pickle.load(stdout))
                except (EOFError, OSError, ValueError, pickle.UnpicklingError) as exc:
                    # EOF or garbage on the pipe: the worker is gone
                    q.put(("dead", repr(exc)))
                    return

        threading.Thread(target=reader, daemon=True).start()
        self.start_error = None
        try:
            pickle.dump(list(_sys.path), self._proc.stdin)
            pickle.dump(self.fn, self._proc.stdin)
            self._proc.stdin.flush()
            status, detail = q.get(timeout=self.startup_timeout)
            if status == "ready":
                return True
            self.start_error = f"worker {status}: {detail}"
        except (pickle.PicklingError, TypeError, AttributeError, OSError) as exc:  # unpicklable fn, broken pipe
            self.start_error = repr(exc)
        except queue.Empty:
            self.start_error = f"worker not ready within {self.startup_timeout} s"
        self.close()
        return False

    def __call__(self, *args) -> tuple[bool, Any]:
        """Return ``(True, value)``, or ``(False, reason)`` on timeout/error."""
        import pickle
        import queue

        if (self._proc is None or self._proc.poll() is not None) and not self._start():
            return False, f"worker did not start ({self.start_error})"
        try:
            pickle.dump(args, self._proc.stdin)
            self._proc.stdin.flush()
            status, value = self._queue.get(timeout=self.timeout)
        except queue.Empty:
            self.close()  # hung: kill the worker, a fresh one starts next call
            return False, "timeout"
        except (OSError, ValueError) as exc:  # broken pipe / closed file: the worker died
            self.close()
            return False, f"worker failed: {exc!r}"
        if status == "ok":
            return True, value
        if status == "dead":
            self.close()
            return False, f"worker died ({value})"
        return False, value

    def close(self):
        """Kill the worker (a new one starts on the next call)."""
        if self._proc is not None:
            if self._proc.poll() is None:
                self._proc.kill()
            import subprocess

            try:
                self._proc.wait(timeout=5)
            except subprocess.TimeoutExpired:  # killed but not reaped yet: the OS finishes it
                pass
            for f in (self._proc.stdin, self._proc.stdout):
                try:
                    f.close()
                except OSError:  # broken pipe on flush of a dead worker's stdin
                    pass
        self._proc = self._queue = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except (OSError, TypeError, AttributeError, ImportError):
            # at interpreter shutdown module globals may already be gone
            pass
