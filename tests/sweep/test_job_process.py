"""Job processes: calls go there and back, a run that kills its job process is a typed
failure and the next call gets a fresh job process, a job process ends with the thread that
made it."""

from __future__ import annotations

import os
import sys
import threading
import time

import pytest

from slamkit.sweep import job_process
from slamkit.sweep.job_process import JobProcess, JobProcessDied, run_in_job_process


def test_a_call_runs_in_another_process_and_prints_do_not_break_the_replies():
    r = JobProcess()
    try:
        assert r.call(abs, -3) == 3
        assert r.call(print, "printed by the job process, on its stderr") is None
        assert r.call(os.getpgid, 0) == os.getpgid(r.pid)
        assert r.pid != os.getpid()
    finally:
        r.close()
    assert not r.alive()


def test_an_exception_comes_back_typed_and_the_process_goes_on():
    r = JobProcess()
    try:
        with pytest.raises(ValueError, match="invalid literal"):
            r.call(int, "not a number")
        assert r.call(len, "four") == 4
    finally:
        r.close()


def test_a_run_that_kills_its_process_is_reported_and_the_next_gets_a_fresh_one():
    assert run_in_job_process(abs, -1) == 1
    with pytest.raises(JobProcessDied, match="exit status 7"):
        run_in_job_process(sys.exit, 7)
    assert run_in_job_process(abs, -2) == 2  # a new job process


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_job_process_ends_with_the_thread_that_started_it():
    made: list[JobProcess] = []

    def work() -> None:
        r = JobProcess()
        r.call(abs, -1)  # started and serving
        made.append(r)

    t = threading.Thread(target=work)
    t.start()
    t.join()
    (r,) = made
    deadline = time.monotonic() + 10.0
    while r.alive() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not r.alive()


def test_execute_task_records_a_dead_job_process_as_a_failed_run(monkeypatch):
    from slamkit.sweep.execute import RunTask, execute_task, plan_sweep
    from slamkit.sweep.spec import parse_spec

    def dies(function, argument):
        raise JobProcessDied("the job process 1 ended (signal 11)")

    monkeypatch.setattr(job_process, "run_in_job_process", dies)
    spec = parse_spec({"sweep": {"estimators": ["dead-reckoning"], "datasets": ["five-features"]}})
    ((key, point),) = plan_sweep(spec)
    outcome = execute_task(RunTask(key, point, "/nonexistent/never-written"))
    assert not outcome.ok
    assert outcome.error == "JobProcessDied: the job process 1 ended (signal 11)"
