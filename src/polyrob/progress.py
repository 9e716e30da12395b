"""One progress line for a whole job: stage k of n, the fraction of the job done, and an ETA.

A command (``run``, ``synth``) declares its stages with their expected
shares of the job (:data:`STAGE_WEIGHTS`); the library's loops report how far
their own work is (:func:`report`: tasks of a bound, iterations of a
synthesis), and :class:`JobProgress` turns that into one figure for the
whole job, never decreasing.  On a terminal it is a tqdm bar; off one
(a pipe, a log file, a batch system) a plain line on stderr at least every
:data:`LINE_EVERY` seconds while a stage runs, so that no stage is silent
for minutes.

The progress reads the clock it is given (``clock``, default
``time.monotonic``) and decides nothing: the tests drive it with a fake clock.
"""

from __future__ import annotations

import re
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager

__all__ = ["JobProgress", "LINE_EVERY", "STAGE_WEIGHTS", "report", "span", "current", "duration_words"]

#: Seconds between two progress lines off a terminal (at most; a line also starts each stage).
LINE_EVERY = 20.0
#: Expected shares of a job by the first word of a stage's title (measured order of magnitude on the arms'
#: default tasks: the synthesis dominates); any other stage counts :data:`OTHER_WEIGHT`.
STAGE_WEIGHTS = {
    "bounds": 0.2,
    "reading": 0.02,
    "synthesis": 0.45,
    "largest": 0.6,
    "analysis": 0.25,
    "validation": 0.1,
    "moving-robot": 0.3,
    "tuning": 0.4,  # per round ("(up to N rounds"): ur5's per-link PID, 3 rounds about 3 times its synthesis' minutes
}
OTHER_WEIGHT = 0.1
#: Largest share of a stage its own reports may claim before it ends (a loop's count is a hint, not a promise).
WITHIN_CAP = 0.95

_current: JobProgress | None = None
_lock = threading.Lock()
#: The part of the current stage that :func:`report` counts in (:func:`span` narrows it for nested loops), per
#: thread: a loop left running in another thread (a batch's in-process worker, an abandoned call) neither moves
#: nor narrows the job's line (two .ci/run runs failed a progress test when the span was one global).
_local = threading.local()


def _current_span() -> tuple[float, float]:
    return getattr(_local, "span", (0.0, 1.0))


def duration_words(seconds: float) -> str:
    """``"4 min 05 s"``, ``"37 s"``."""
    seconds = max(0.0, float(seconds))
    if seconds < 60:
        return f"{seconds:.0f} s"
    minutes, sec = divmod(int(round(seconds)), 60)
    if minutes < 60:
        return f"{minutes} min {sec:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"


def _short(title: str) -> str:
    """A stage's name: its title up to a colon, a parenthesis or " into"."""
    for cut in (":", " (", " into "):
        title = title.split(cut)[0]
    return title.strip()


def report(done: float, total: float) -> None:
    """A library loop's own progress (``done`` of ``total``) inside the current stage of the current job, if any.

    Inside a :func:`span` the loop's count fills that span's part of the stage.
    """
    job = _current
    if job is not None and total > 0 and job.reported_from_here():
        lo, hi = _current_span()
        job.within(lo + (hi - lo) * min(max(done / total, 0.0), 1.0))


@contextmanager
def span(lo: float, hi: float) -> Iterator[None]:
    """Reports inside the block fill the part ``[lo, hi]`` of the enclosing span (nested loops), then ``hi`` is done.

    An outer loop that runs an inner one per step (the bandwidth search: a
    synthesis per factor) gives each step its part of the stage; the inner
    loop's own :func:`report` calls then move the line within that part
    instead of claiming the whole stage.

    Examples
    --------
    >>> import io
    >>> from polyrob.progress import JobProgress, report, span
    >>> job = JobProgress(["largest bandwidth"], stream=io.StringIO(), clock=lambda: 0.0)
    >>> job.start() is job and job._stop.set() is None   # the current job; no ticking thread in the example
    True
    >>> job.begin(1, "largest bandwidth")
    >>> with span(0.5, 0.75):
    ...     report(1, 2)                  # half of the inner loop: 0.625 of the stage
    >>> round(job.share, 3)               # the block ended: its part is done
    0.75
    >>> job.stop()
    """
    outer = _current_span()
    a, b = outer
    _local.span = (a + (b - a) * float(lo), a + (b - a) * float(hi))
    try:
        yield
    finally:
        _local.span = outer
        job = _current
        if job is not None and job.reported_from_here():
            job.within(a + (b - a) * float(hi))


def current() -> JobProgress | None:
    """The job whose progress is shown now (``None``: none)."""
    return _current


class JobProgress:
    """The progress of a whole job through its stages.

    Parameters
    ----------
    titles : sequence of str
        The stages' titles, in order (a stage's weight is
        :data:`STAGE_WEIGHTS` of its first word).  Stages not known yet may
        be given as ``""``; :meth:`begin` names them.
    terminal : bool
        A tqdm bar (True) or plain lines every :data:`LINE_EVERY` s (False).
    stream : file, optional
        Where lines and the bar go (default ``sys.stderr``).
    clock : callable, optional
        Seconds (default ``time.monotonic``).
    every : float
        Seconds between two plain lines.

    Examples
    --------
    >>> import io
    >>> t = [0.0]
    >>> out = io.StringIO()
    >>> job = JobProgress(["bounds", "synthesis"], terminal=False, stream=out, clock=lambda: t[0])
    >>> job.begin(1, "bounds")
    >>> t[0] = 30.0; job.within(0.5); job.tick()
    >>> out.getvalue().splitlines()[-1]
    'progress: stage 1 of 2 (bounds), 15 % of the job, 30 s elapsed, about 2 min 45 s left'
    """

    def __init__(
        self,
        titles: Sequence[str],
        *,
        terminal: bool = False,
        stream=None,
        clock: Callable[[], float] | None = None,
        every: float = LINE_EVERY,
    ):
        self.titles = list(titles)
        self.weights = [self._weight(t) for t in self.titles]
        self.terminal, self.every = bool(terminal), float(every)
        self.stream = stream if stream is not None else sys.stderr
        self.clock = clock or time.monotonic
        self.t0 = self.last_line = self.clock()
        self.stage = 0  # 1-based; 0: not started
        self.share = 0.0  # of the current stage, from the library's reports
        self.best = 0.0  # the fraction shown so far: it never decreases
        self._bar = None
        self._stop = threading.Event()
        self._thread = None

    @staticmethod
    def _weight(title: str) -> float:
        """:data:`STAGE_WEIGHTS` of the title's first word, times ``N`` for a stage of ``"(up to N rounds"``."""
        word = title.split()[0].rstrip(":,") if title.split() else ""
        rounds = re.search(r"\(up to (\d+) rounds?", title)
        return STAGE_WEIGHTS.get(word, OTHER_WEIGHT) * (max(1, int(rounds.group(1))) if rounds else 1)

    @property
    def n(self) -> int:
        return len(self.titles)

    def begin(self, k: int, title: str) -> None:
        """Stage ``k`` (1-based) starts."""
        with _lock:
            if k > self.n:  # a stage the command did not announce: the job grew
                self.titles += [""] * (k - self.n)
                self.weights += [OTHER_WEIGHT] * (k - len(self.weights))
            self.titles[k - 1] = title
            self.weights[k - 1] = self._weight(title)
            self.stage, self.share = k, 0.0
        self._show(force=True)

    def reported_from_here(self) -> bool:
        """Whether the calling thread is the one that started the job (the library's reports count from it only)."""
        return getattr(self, "_owner", threading.get_ident()) == threading.get_ident()

    def within(self, share: float) -> None:
        """The current stage is ``share`` done (its own loops' count; capped at :data:`WITHIN_CAP`)."""
        with _lock:
            self.share = max(self.share, min(float(share), WITHIN_CAP))

    @property
    def fraction(self) -> float:
        """The job's fraction done: the finished stages' weights and the current one's share, never decreasing."""
        total = sum(self.weights) or 1.0
        k = self.stage
        if k == 0:
            return 0.0
        done = sum(self.weights[: k - 1]) + self.weights[k - 1] * self.share
        self.best = max(self.best, min(done / total, 1.0))
        return self.best

    def line(self) -> str:
        """``progress: stage k of n (title), F % of the job, T elapsed, about E left``."""
        f = self.fraction
        elapsed = self.clock() - self.t0
        title = _short(self.titles[self.stage - 1]) if self.stage else ""
        head = f"progress: stage {self.stage} of {self.n}" + (f" ({title})" if title else "")
        eta = f"about {duration_words(elapsed * (1 - f) / f)} left" if f >= 0.01 else "time left not known yet"
        return f"{head}, {100 * f:.0f} % of the job, {duration_words(elapsed)} elapsed, {eta}"

    def tick(self) -> None:
        """Called every second or so while a stage runs: a line when :attr:`every` seconds passed, or the bar."""
        self._show(force=False)

    def _show(self, force: bool) -> None:
        now = self.clock()
        if self.terminal:
            bar = self._ensure_bar()
            bar.n = int(round(1000 * self.fraction))
            bar.set_description_str(self.line().split(",")[0].replace("progress: ", ""), refresh=False)
            bar.set_postfix_str(self.line().split(", ", 2)[-1], refresh=False)
            bar.refresh()
            return
        if force or now - self.last_line >= self.every:
            self.last_line = now
            print(self.line(), file=self.stream, flush=True)

    def _ensure_bar(self):
        if self._bar is None:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=1000, file=self.stream, leave=False, bar_format="{desc} |{bar}| {postfix}")
        return self._bar

    def start(self) -> JobProgress:
        """Make this the current job and tick it every second from a daemon thread (until :meth:`stop`)."""
        global _current
        _current = self
        self._owner = threading.get_ident()

        def beat():
            while not self._stop.wait(1.0):
                try:
                    self.tick()
                except (ValueError, OSError):  # the stream was closed under us: the command is over
                    return

        self._thread = threading.Thread(target=beat, name="polyrob-progress", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """No more lines; the bar is removed."""
        global _current
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        if _current is self:
            _current = None
        if self._bar is not None:
            self._bar.close()
            self._bar = None


def stop_current() -> None:
    """Stop the current job's progress, if any (the command is over)."""
    job = _current
    if job is not None:
        job.stop()
