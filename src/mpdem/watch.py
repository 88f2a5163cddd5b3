"""The set-up's watch: progress said at least every half minute, and SIGTERM or SIGINT honoured
within seconds, before the first step.

A new run's set-up (the bed, the pour's insertion, the checks of the initial state, the rows sent
to their ranks, the first neighbour-list build) is cut into short calls of work (``build``:
``insert_random`` in batches, ``make_bed``'s settle in calls of ``SETTLE_ROW_STEPS``
sphere-steps). Between two calls the work looks at its ``Watch``: a progress line when
``every`` seconds have passed since the last line (on rank 0, through the run's log), and a stop
signal received since the set-up began ends it with ``Interrupted``.

Nothing is saved during the set-up, so a stop there ends the process at once: one line, exit
status 128 + the signal's number (143 for SIGTERM, 130 for SIGINT, as a shell reports a process
ended by that signal), no state file. A stop must reach every rank together, or the others would
wait in a collective for ever: work that every rank does alike (the insertion, the making of the
bed, the first build) looks with ``everywhere=True``, which agrees the signals by one max over the
ranks. SIGUSR1, a batch system's early warning, is not a stop here: the run's first step takes it
and writes a checkpoint (``driver.simulation``).

Some work has no short calls to look between: numba compiling or loading its kernels (the first
calls of a process), the first neighbour-list build. There a guard thread, told of each signal at
once through ``signal.set_wakeup_fd``, ends the process itself when a stop has waited ``GRACE``
seconds for a look (on a rank other than 0 a second more, so that rank 0 says the line; only in
the command line's process, ``ENDS_PROCESS``): the same line on rank 0, the same status,
``os._exit``. No file is open for writing under its real name during the set-up (every file is
written under a temporary name and renamed); under mpiexec the launcher then ends the other ranks.
The guard also says a line when no look has said one for ``every`` + ``GUARD_LATER`` seconds
(28 s). It needs the interpreter's lock, which a running numba kernel holds, so the kernels stay
in short calls all the same.
"""
from __future__ import annotations

import os
import select
import signal
import sys
import threading
import time

from .errors import Interrupted

# the signals that stop a set-up
STOP = (signal.SIGTERM, signal.SIGINT)
# the longest time between two progress lines of a set-up [s] (a call of work lasts a few seconds
# at most, so a line comes well within half a minute)
EVERY = 20.0
# whether the guard thread may end the process: the command line's (``python -m mpdem``) alone, never
# a Python program's that called ``mpdem.run`` (there a stop waits for a look and raises)
ENDS_PROCESS = False
# seconds a stop signal waits for a look before the guard thread ends the process [s]
GRACE = 2.0
# seconds after ``every`` at which the guard says its line when no look has said one [s]
GUARD_LATER = 8.0
# how to go on after a new run's stop (its line's end)
AGAIN_NEW = "start the run again (with --force to reuse its directory)"
# the environment variable that sets another such time [s] (the tests: lines after every call)
EVERY_ENV = "MPDEM_SETUP_PROGRESS"


def every_default():
    """``$MPDEM_SETUP_PROGRESS`` seconds if set (a number >= 0), else ``EVERY`` [s]."""
    try:
        t = float(os.environ.get(EVERY_ENV, EVERY))
    except ValueError:
        return EVERY
    return t if t >= 0 else EVERY


class Watch:
    """The looks of a set-up between its calls of work.

    Parameters
    ----------
    log : callable
        Takes a progress line (the run's ``Logger``: rank 0 prints it and keeps it in the log).
    net : parallel.Channel or None
        The run's ranks (None: one).
    signals : list or None
        Signal numbers received so far; the watch's handlers append to it (the command line's
        list, shared with the run's loop).
    every : float or None
        Seconds between progress lines at most [s]; None: ``every_default()``.
    clock : callable
        Seconds, monotonic [s].
    again : str
        How to go on after a stop, in the stop's line (a new run's: start it again).

    Use it as a context manager: inside, SIGTERM and SIGINT are recorded instead of ending the
    process (SIGINT raises no KeyboardInterrupt), and the handlers before it are back after it.
    """

    def __init__(self, log, net=None, signals=None, every=None, clock=time.monotonic, again=AGAIN_NEW):
        self.log, self.net = log, net
        self.signals = [] if signals is None else signals
        self.every, self.clock = every_default() if every is None else every, clock
        self.t0 = self.last = clock()
        self.phase = "the set-up"
        self.again = again
        self._old = {}
        self._guard, self._stopping = None, False

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            # a SIGINT ignored by whoever started us (a background job of a script) stays ignored
            self._old = {s: signal.signal(s, self._record) for s in STOP
                         if not (s == signal.SIGINT and signal.getsignal(s) == signal.SIG_IGN)}
            self._start_guard()
        return self

    def __exit__(self, *exc):
        self._stop_guard()
        for s, h in self._old.items():
            signal.signal(s, h)
        self._old = {}
        return False

    # -- the guard thread: a stop that no look takes within GRACE seconds ends the process --
    def _start_guard(self):
        """The guard thread; told of the signals through a wakeup fd where it may end the process
        (``ENDS_PROCESS``: a Python program keeps its own wakeup fd, an event loop's)."""
        self._stopping, self._pipe = False, None
        if ENDS_PROCESS:
            try:
                r, w = os.pipe()
                os.set_blocking(w, False)
                self._old_fd = signal.set_wakeup_fd(w)
                self._pipe = (r, w)
            except (OSError, ValueError):
                self._pipe = None
        self._guard = threading.Event()
        threading.Thread(target=self._watch_signals, args=(self._pipe[0] if self._pipe else None, self._guard),
                         daemon=True, name="mpdem-setup-guard").start()

    def _stop_guard(self):
        if getattr(self, "_guard", None) is None:
            return
        self._guard.set()
        self._guard = None
        if self._pipe is not None:
            signal.set_wakeup_fd(self._old_fd)
            # the thread closes the pipe's read end; this side closes its write end
            os.close(self._pipe[1])

    def _watch_signals(self, fd, done):
        """The guard thread: the stop signals as they come (the wakeup fd's bytes, ``fd``; None: none),
        the end of the process when one has waited ``GRACE`` seconds for a look, and a line when no
        look has said one for a while."""
        first, sig = None, 0
        # rank 0 first, so that its line is said before the launcher ends the other ranks
        grace = GRACE if self.net is None or self.net.rank == 0 else GRACE + 1.0
        try:
            while not done.is_set():
                if fd is None:
                    done.wait(0.25)
                elif select.select([fd], [], [], 0.25)[0]:
                    try:
                        got = os.read(fd, 64)
                    except OSError:
                        got = b""
                    stops = [b for b in got if b in STOP]
                    if stops:
                        sig = max(sig, *stops)
                        first = first if first is not None else self.clock()
                if first is not None and self.clock() - first >= grace and not done.is_set() and not self._stopping:
                    self._end_now(sig)
                # no look for a while (numba compiling): a line all the same, later than a look's would be
                if self.every and self.clock() - self.last >= self.every + GUARD_LATER and not done.is_set():
                    self.say(f"set-up: {self.phase} goes on")
        finally:
            if fd is not None:
                os.close(fd)

    def _end_now(self, sig):
        """End the process from the guard thread: the stop's line (rank 0), its status."""
        e = interrupted(sig, self.phase, self.again)
        note = getattr(self.log, "note", None)
        if self.net is None or self.net.rank == 0:
            if note is not None:
                note(f"stop: {e}")
            sys.stderr.write(f"mpdem: {e}\n")
            sys.stderr.flush()
        sys.stdout.flush()
        os._exit(e.status)

    def _record(self, signum, frame):
        self.signals.append(int(signum))

    def pending(self):
        """The highest stop signal received so far (0: none)."""
        return max((s for s in self.signals if s in STOP), default=0)

    def elapsed(self):
        """Seconds since the set-up began [s]."""
        return self.clock() - self.t0

    def begin(self, phase, line=None):
        """A new phase of the set-up (named in a stop's message), with a line said at once."""
        self.phase = phase
        if line:
            self.say(line)

    def say(self, line):
        """Say ``line`` now, with the seconds since the set-up began."""
        self.log(f"{line} ({self.elapsed():.0f} s)")
        self.last = self.clock()

    def __call__(self, line=None, everywhere=False):
        """A look between two calls of work: raise ``Interrupted`` on a stop signal, else say
        ``line`` (a callable giving it, or a str) if ``every`` seconds passed since the last line.

        Parameters
        ----------
        line : str, callable or None
        everywhere : bool
            Every rank looks here together (collective): the signals are agreed over the ranks,
            and a stop raises on all of them.
        """
        sig = self.pending()
        if everywhere and self.net is not None and self.net.parallel:
            sig = int(self.net.max_many([float(sig)])[0])
        if sig:
            self._stopping = True
            e = interrupted(sig, self.phase, self.again)
            note = getattr(self.log, "note", None)     # the log file keeps it too (the run's Logger)
            if note is not None:
                note(f"stop: {e}")
            raise e
        if line is not None and self.clock() - self.last >= self.every:
            self.say(line() if callable(line) else line)



def interrupted(sig, phase, again=AGAIN_NEW):
    """The ``Interrupted`` of stop signal ``sig`` received during ``phase`` (agreed: every rank raises it);
    ``again`` says how to go on."""
    name = signal.Signals(sig).name
    e = Interrupted(f"stopped by {name} during {phase}, before the first step: nothing was saved; {again}",
                    128 + sig)
    e.agreed = True
    return e
