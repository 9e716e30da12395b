"""One Ctrl-C ends a command within seconds, worker processes included.

Python runs a SIGINT handler only between bytecodes of the main thread: a
parent blocked joining a process pool, or inside a long C routine, would not
see it, and pool workers left alive keep the interpreter from exiting.  A
wake-up file descriptor (:func:`signal.set_wakeup_fd`) is written by the C
level handler at once, whatever the main thread does; a watchdog thread
reading it stops this process's multiprocessing children and, if the
process is still alive after a grace period, ends it with status 130.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

__all__ = ["EXIT_INTERRUPTED", "InterruptGuard", "keep", "interrupted_line"]

EXIT_INTERRUPTED = 130
GRACE_SECONDS = 4.0


#: Results a command has written so far (complete files, written atomically): an interrupt keeps them and says so.
_KEPT: list[str] = []


def keep(path) -> None:
    """Record a finished result file: a later interrupt keeps it and :func:`interrupted_line` names it."""
    if str(path) not in _KEPT:
        _KEPT.append(str(path))


def interrupted_line() -> str:
    """The one line an interrupted command prints: what it kept, if anything."""
    kept = f"; kept {', '.join(_KEPT)}" if _KEPT else ""
    return f"polyrob: interrupted{kept}"


def stop_children(timeout: float = 1.0) -> None:
    """Terminate (then kill) the multiprocessing children of this process."""
    import multiprocessing

    from polyrob.workers import stop_processes

    stop_processes(multiprocessing.active_children(), timeout)


class InterruptGuard:
    """Context manager: a watchdog for SIGINT while a command runs (main thread only).

    ``interrupted`` tells whether a SIGINT arrived; after one, the watchdog
    stops the children at once and ends the process after
    :data:`GRACE_SECONDS` unless it has exited by then (the main thread has
    that long to remove temporary files and print its line).
    """

    def __init__(self, grace: float = GRACE_SECONDS):
        self.grace = grace
        self.interrupted = threading.Event()
        self._fds = None
        self._previous_fd = -1

    def _unraisable(self, unraisable) -> None:
        # a SIGINT landing in an at-fork or __del__ hook (logging's lock release
        # while a pool forks) is "ignored" with a traceback: it is the interrupt
        if issubclass(unraisable.exc_type, KeyboardInterrupt):
            self.interrupted.set()
            return
        self._previous_hook(unraisable)

    def __enter__(self):
        _KEPT.clear()  # a new command: nothing of its own kept yet
        if threading.current_thread() is not threading.main_thread():
            return self
        self._previous_hook = sys.unraisablehook
        sys.unraisablehook = self._unraisable
        r, w = os.pipe()
        os.set_blocking(w, False)
        try:
            self._previous_fd = signal.set_wakeup_fd(w, warn_on_full_buffer=False)
        except (ValueError, OSError):  # not the main interpreter: no watchdog
            os.close(r)
            os.close(w)
            return self
        self._fds = (r, w)
        threading.Thread(target=self._watch, args=(r,), name="polyrob-sigint", daemon=True).start()
        return self

    def _watch(self, r: int) -> None:
        pipe = os.fdopen(r, "rb", buffering=0)  # closed here, never under a running read
        while True:
            data = pipe.read(64)
            if not data:  # the write end was closed: the command is over
                pipe.close()
                return
            if signal.SIGINT in data:
                break
        # The read end stays open until the process ends: the write end is the wake-up fd
        # until the main thread leaves the guard, and a signal written to a pipe without a
        # reader is "Exception ignored when trying to write to the signal wakeup fd:
        # BrokenPipeError" with a traceback (a second Ctrl-C, seen in 1-2 of 10 runs).
        self.interrupted.set()
        stop_children()
        time.sleep(self.grace)
        os._exit(EXIT_INTERRUPTED)

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None and issubclass(exc_type, KeyboardInterrupt):
            # the main thread may see the KeyboardInterrupt before the watchdog reads the pipe:
            # it is the interrupt all the same (and a second Ctrl-C must now be ignored)
            self.interrupted.set()
        if getattr(self, "_previous_hook", None) is not None and not self.interrupted.is_set():
            sys.unraisablehook = self._previous_hook
        if self._fds is None:
            return False
        if self.interrupted.is_set():
            # the command is ending: a second Ctrl-C must not raise KeyboardInterrupt in the
            # clean-up or in the interpreter's exit handlers (a traceback "ignored in atexit")
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.set_wakeup_fd(self._previous_fd)
        # no signal writes to the pipe any more: close the write end (after an interrupt too);
        # the watchdog reads EOF, closes its end and returns, or is busy ending the process
        os.close(self._fds[1])
        return False
