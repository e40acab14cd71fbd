"""Job processes: each run of a sweep in a single-threaded Python process of its own.

A Dask worker runs its tasks on a thread beside the threads of its event loop, heartbeats
and profiler. Measured on this project's sweep benchmark, that alone makes a one-second run
20-50 % slower than in a plain process (``docs/sweeps.md``, "What Dask costs"), the cause
inside CPython and NumPy rather than Dask. So a worker thread does not run the job itself:
it hands the task to a *job process*, a child process that imports slamkit once and then runs
one task after another, reading pickled tasks on its stdin and writing the outcomes on its
stdout. Each worker thread has its own job process (a thread never waits on another's).

A job process does not outlive its worker: on Linux it asks the kernel for ``SIGKILL`` when the
thread that started it ends (``PR_SET_PDEATHSIG``), so a killed worker leaves no orphan
writing a run folder the scheduler is about to re-run elsewhere; elsewhere it ends at the end
of the task it is on, when it reads the end of its closed stdin. A run that kills its job process
(a crash in compiled code, the kernel's out-of-memory killer) is a failed run with the exit
status; the next task starts a fresh job process.

This module imports neither Dask nor NumPy: it moves pickles.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from typing import IO, Any

__all__ = ["JobProcess", "JobProcessDied", "run_in_job_process"]

PR_SET_PDEATHSIG = 1
"""``prctl`` option: the signal the kernel sends a process when its parent thread ends."""


class JobProcessDied(RuntimeError):
    """The job process ended while running a task (its exit status in the message)."""


class JobProcess:
    """One job process: start it, give it a call ``(function, argument)``, get the result back.

    ``function`` must be importable by name (a module-level function of an installed
    package), as it is pickled by reference.
    """

    def __init__(self) -> None:
        # The same interpreter, environment and working folder, so the same slamkit.
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "slamkit.sweep.job_process", str(os.getpid())],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )

    @property
    def pid(self) -> int:
        return self._proc.pid

    def alive(self) -> bool:
        return self._proc.poll() is None

    def call(self, function: Callable[[Any], Any], argument: Any) -> Any:
        """``function(argument)`` in the job process; :class:`JobProcessDied` if it ends
        meanwhile."""
        stdin, stdout = self._proc.stdin, self._proc.stdout
        assert stdin is not None and stdout is not None
        try:
            pickle.dump((function, argument), stdin, protocol=pickle.HIGHEST_PROTOCOL)
            stdin.flush()
            ok, result = pickle.load(stdout)
        except (EOFError, BrokenPipeError, pickle.UnpicklingError):
            status = self._proc.wait()
            how = f"signal {-status}" if status < 0 else f"exit status {status}"
            raise JobProcessDied(f"the job process {self.pid} ended ({how})") from None
        if not ok:
            raise result
        return result

    def close(self) -> None:
        """End the job process (it reads the end of its stdin and returns)."""
        if self._proc.stdin is not None:
            self._proc.stdin.close()
        self._proc.wait()


_LOCAL = threading.local()


def run_in_job_process(function: Callable[[Any], Any], argument: Any) -> Any:
    """``function(argument)`` in this thread's job process, started on first use (and
    again after one died)."""
    proc: JobProcess | None = getattr(_LOCAL, "proc", None)
    if proc is None or not proc.alive():
        proc = _LOCAL.proc = JobProcess()
    try:
        return proc.call(function, argument)
    except JobProcessDied:
        _LOCAL.proc = None
        raise


def _die_with_parent(parent: int) -> None:
    """On Linux, be killed when the thread that started this process ends; exit now if the
    parent has already gone (this process was orphaned before it could ask)."""
    if sys.platform.startswith("linux"):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent:
        sys.exit(0)


def serve(requests: IO[bytes], replies: IO[bytes]) -> None:
    """Read ``(function, argument)`` pickles from ``requests`` until its end; for each,
    write ``(True, function(argument))``, or ``(False, exception)`` for the exception it
    raised, to ``replies``."""
    while True:
        try:
            function, argument = pickle.load(requests)
        except EOFError:
            return
        try:
            reply = pickle.dumps((True, function(argument)), protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:  # handed back to the caller, who decides
            reply = _exception_reply(exc)
        replies.write(reply)
        replies.flush()


def _exception_reply(exc: Exception) -> bytes:
    """``(False, exc)`` pickled; an exception that does not pickle goes as a
    :class:`RuntimeError` with its type and message."""
    try:
        return pickle.dumps((False, exc), protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:
        text = f"{type(exc).__name__}: {exc}"
        return pickle.dumps((False, RuntimeError(text)), protocol=pickle.HIGHEST_PROTOCOL)


def main(argv: list[str]) -> None:
    """The job process: the replies go to a private copy of stdout, and anything a run prints on
    stdout goes to stderr instead. Ctrl-C is the parent's to handle."""
    _die_with_parent(int(argv[0]))
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    replies = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    serve(sys.stdin.buffer, replies)


if __name__ == "__main__":
    main(sys.argv[1:])
