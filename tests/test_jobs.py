"""The execution layer (issue 22): the same results serially, in local processes and on Dask; a
worker killed mid-run loses nothing; a rerun resumes from the results file.

The Dask tests start a real :class:`distributed.LocalCluster` (2 worker processes) and a scheduler
and workers as separate processes on 127.0.0.1, the way a user starts them on a cluster; they skip
with a reason when the optional ``[cluster]`` extra is not installed.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from jobs_helpers import fail_on, short_ride, slow_square
from ptw_env.jobs import JobsError, executor_name, run_jobs

HERE = Path(__file__).resolve().parent
RIDES = [((s, v), (s, v)) for s in (0, 1, 2) for v in (30.0, 60.0)]

try:
    import distributed  # noqa: F401

    HAVE_DASK = True
except ImportError:  # pragma: no cover - CI installs the extra
    HAVE_DASK = False
needs_dask = pytest.mark.skipif(not HAVE_DASK, reason="the optional [cluster] extra (dask[distributed]) is not installed")


@pytest.fixture(scope="module")
def serial():
    return run_jobs(short_ride, RIDES, progress=False)


def test_local_processes_give_the_serial_results_bit_for_bit(serial):
    assert run_jobs(short_ride, RIDES, workers=2, progress=False) == serial
    assert list(serial) == [k for k, _ in RIDES]  # the jobs' order, whatever the order of completion


@needs_dask
def test_a_dask_local_cluster_gives_the_serial_results_bit_for_bit(serial, monkeypatch):
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]))
    assert run_jobs(short_ride, RIDES, workers=2, scheduler="local", progress=False) == serial


def _start(args: list[str], env: dict) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", *args], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _wait_for(pred, timeout: float, what: str) -> None:
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.1)


@needs_dask
def test_scheduler_and_workers_started_by_hand_and_a_worker_killed_mid_run(tmp_path, serial):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]))
    sfile = tmp_path / "scheduler.json"
    procs = [_start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                     "--scheduler-file", str(sfile)], env)]
    try:
        _wait_for(sfile.exists, 60, "the scheduler file")
        _wait_for(lambda: "address" in sfile.read_text() if sfile.stat().st_size else False, 30, "the scheduler address")
        address = json.loads(sfile.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for _ in range(2):
            procs.append(_start(["distributed.cli.dask_worker", "--scheduler-file", str(sfile), "--nthreads", "1",
                                 "--no-dashboard", "--no-nanny"], env))
        from distributed import Client

        with Client(address, timeout="30s") as c:
            c.wait_for_workers(2, timeout=60)
        # a small sweep on the cluster: the serial numbers
        assert run_jobs(short_ride, RIDES, scheduler=address, progress=False) == serial
        # kill one worker (SIGKILL, no goodbye) once a few results are in: nothing is lost
        res = tmp_path / "squares.jsonl"
        jobs = [(i, (i, 0.3)) for i in range(16)]

        def killer():
            _wait_for(lambda: res.exists() and len(res.read_text().splitlines()) >= 3, 60, "three results")
            procs[1].send_signal(signal.SIGKILL)

        th = threading.Thread(target=killer, daemon=True)
        th.start()
        out = run_jobs(slow_square, jobs, scheduler=address, results=res, progress=False)
        th.join(timeout=5)
        assert procs[1].wait(timeout=10) == -signal.SIGKILL  # the worker really died under the run
        assert out == {i: i * i for i in range(16)}
        lines = [json.loads(x) for x in res.read_text().splitlines()]
        assert sorted(x["key"] for x in lines) == list(range(16))  # each result written once
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:  # pragma: no cover
                p.kill()


def test_a_rerun_resumes_from_the_results_file(tmp_path):
    res = tmp_path / "r.jsonl"
    first = run_jobs(slow_square, [(i, (i, 0.0)) for i in range(3)], results=res, progress=False)
    with res.open("a") as f:
        f.write('{"key": 7, "resu')  # a line cut by a crash
    calls = tmp_path / "calls"
    out = run_jobs(_counting_square, [(i, (i, str(calls))) for i in range(8)], results=res, progress=False)
    assert out == {i: i * i for i in range(8)} and {i: out[i] for i in range(3)} == first
    assert sorted(int(x) for x in calls.read_text().split()) == [3, 4, 5, 6, 7]  # only the missing ones ran


def _counting_square(x: int, calls: str) -> int:
    with open(calls, "a") as f:
        f.write(f"{x}\n")
    return x * x


def test_bad_settings_are_refused(tmp_path, monkeypatch):
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)
    assert executor_name() == "serial" and executor_name(4) == "processes" and executor_name(2, "local") == "local"
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "tcp://127.0.0.1:8786")
    assert executor_name() == "tcp://127.0.0.1:8786"
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS")
    with pytest.raises(JobsError, match="workers"):
        run_jobs(pow, [], workers=0)
    with pytest.raises(JobsError, match="scheduler"):
        run_jobs(pow, [], scheduler="8786")
    with pytest.raises(JobsError, match="distinct"):
        run_jobs(pow, [("a", (1, 2)), ("a", (2, 2))], progress=False)
    with pytest.raises(JobsError, match="not a regular file"):
        run_jobs(pow, [("a", (1, 2))], results=tmp_path, progress=False)
    with pytest.raises(JobsError, match="strict JSON"):
        run_jobs(float, [("x", ("nan",))], results=tmp_path / "x.jsonl", progress=False)
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if the extra were not installed
    with pytest.raises(JobsError, match=r"ptw-assist\[cluster\]"):
        run_jobs(pow, [("a", (1, 2))], scheduler="local", progress=False)


def test_a_failing_job_raises_its_error_and_keeps_the_finished_ones(tmp_path):
    res = tmp_path / "r.jsonl"
    with pytest.raises(ValueError, match="job 5 failed"):
        run_jobs(fail_on, [(i, (i, 5)) for i in range(6)], results=res, progress=False)
    assert [json.loads(x)["key"] for x in res.read_text().splitlines()] == [0, 1, 2, 3, 4]
    res2 = tmp_path / "p.jsonl"  # the same from a worker process, in a fresh file: the bad job fails
    with pytest.raises(ValueError, match="job 0 failed"):  # last (1 s), after the 7 others finished
        run_jobs(fail_on, [(i, (i, 0, 1.0)) for i in range(8)], workers=2, results=res2, progress=False)
    assert sorted(json.loads(x)["key"] for x in res2.read_text().splitlines()) == list(range(1, 8))


def test_keys_that_print_alike_are_different_jobs():
    assert run_jobs(str, [(1, (1,)), ("1", ("one",))], progress=False) == {1: "1", "1": "one"}
