"""One execution layer for independent jobs: serial, local processes, or a Dask cluster (issue 22).

Evaluations over seeds, sweeps over parameters and fleets of ride logs are maps of one function over
independent jobs. :func:`run_jobs` runs such a map on

* ``serial``: one after the other in this process (``workers=1``, no scheduler);
* local processes (``workers=N``, the default executor; no extra dependency):
  :class:`concurrent.futures.ProcessPoolExecutor`, started by ``spawn`` (a ``fork`` of a process
  whose numba kernels have started OpenMP threads is unsafe and is killed), one BLAS/OpenMP/numba
  thread per worker process (as Dask's workers);
* a Dask cluster (``scheduler="tcp://HOST:PORT"``, or the ``DASK_SCHEDULER_ADDRESS`` environment
  variable): :class:`distributed.Client` on that scheduler; ``scheduler="local"`` starts a
  :class:`distributed.LocalCluster` of ``workers`` processes on this machine. Dask is the optional
  extra ``pip install "ptw-assist[cluster]"``.

What it guarantees, whatever the executor:

* **the same results**: a job carries everything it needs, its seed included (seeds are per job,
  never per worker), so the function gives the same numbers wherever it runs;
* **nothing finished is lost**: with ``results=PATH`` every result is appended to a JSON-lines file
  as it arrives (flushed and synced), one line per job, ``{"key": ..., "result": ...}``. A rerun
  with the same file skips the keys it holds and runs only the rest; a line cut by a crash is
  ignored (and its job rerun). On Dask a worker that dies has its unfinished jobs rescheduled on
  the others (the scheduler's own retry), and the finished ones are already on the client;
* a progress bar on the client (tqdm), unless ``progress=False``.

Results must be JSON-serialisable when ``results`` is given (numbers, strings, lists, dicts;
strict JSON, so no NaN or inf), and the function must be importable by the workers (a module-level
function, not a lambda), as for any process pool.

>>> from ptw_env.jobs import run_jobs
>>> run_jobs(pow, [("a", (2, 3)), ("b", (3, 2))], progress=False)
{'a': 8, 'b': 9}
"""

from __future__ import annotations

import contextlib
import json
import logging
import multiprocessing
import os
from collections.abc import Callable, Hashable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Any

#: Environment variable naming a Dask scheduler (Dask's own convention).
SCHEDULER_ENV = "DASK_SCHEDULER_ADDRESS"


class JobsError(ValueError):
    """A bad executor setting (workers, scheduler), a results file that cannot be used, or a missing extra."""


def _executor(workers: int, scheduler: str | None) -> str:
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise JobsError(f"workers must be a positive integer, got {workers!r}")
    if scheduler is None:
        scheduler = os.environ.get(SCHEDULER_ENV) or None
    if scheduler is not None:
        if not isinstance(scheduler, str) or not (scheduler == "local" or "://" in scheduler):
            raise JobsError(f"scheduler must be 'local' or an address such as tcp://HOST:PORT, got {scheduler!r}")
        return scheduler
    return "serial" if workers == 1 else "processes"


def echo(x: Any) -> Any:
    """The trivial job (returns its argument): what ``scripts/bench_jobs.py`` measures the per-job overhead with."""
    return x


def executor_name(workers: int = 1, scheduler: str | None = None) -> str:
    """Which executor :func:`run_jobs` uses for these settings: ``serial``, ``processes``, ``local`` (a
    Dask LocalCluster) or the scheduler's address."""
    return _executor(workers, scheduler)


def _load_done(path: Path) -> dict[str, Any]:
    """Keys and results already in a results file (a line cut by a crash is skipped)."""
    done: dict[str, Any] = {}
    if not path.exists():
        return done
    if not path.is_file():
        raise JobsError(f"results: {path} is not a regular file")
    with path.open("r", encoding="utf-8") as f:
        for line in f:
            try:
                row = json.loads(line)
                done[_key_text(row["key"])] = row["result"]
            except (ValueError, KeyError, TypeError):
                continue  # an incomplete last line: that job runs again
    return done


def _key_text(key: Hashable) -> str:
    """The key's JSON text: what a results file holds, and what tells two keys apart (1 and "1" differ)."""
    return json.dumps(key, sort_keys=True)


class _Sink:
    """Appends each finished result to the results file, synced, as it arrives."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self._f = None
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._f = path.open("a", encoding="utf-8")

    def put(self, key: Hashable, result: Any) -> None:
        if self._f is None:
            return
        try:
            line = json.dumps({"key": key, "result": result}, sort_keys=True, allow_nan=False)
        except (TypeError, ValueError) as exc:  # NaN/inf, or not JSON at all
            raise JobsError(f"job {key!r}: its result cannot go to the results file, which is strict JSON ({exc}); "
                            "return finite numbers (say what diverged instead)") from None
        self._f.write(line + "\n")
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        if self._f is not None:
            self._f.close()


def _bar(progress: bool, total: int, initial: int, desc: str):
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit="job", disable=not progress)


def run_jobs(fn: Callable[..., Any], jobs: Iterable[tuple[Hashable, Sequence[Any]]], *, workers: int = 1,
             scheduler: str | None = None, results: str | os.PathLike | None = None, progress: bool = True,
             desc: str = "jobs") -> dict[Hashable, Any]:
    """Run ``fn(*args)`` for every ``(key, args)`` of ``jobs``; return ``{key: result}`` in the jobs' order.

    Parameters
    ----------
    fn : callable
        A module-level function (the workers import it).
    jobs : iterable of (key, args)
        Distinct hashable keys with a JSON form (strings, numbers, tuples of them: a tuple is
        saved as a JSON list and read back as the same key); ``args`` a tuple.
    workers : int
        Local processes (1: serial), or the size of a ``scheduler="local"`` Dask cluster.
    scheduler : str, optional
        ``"tcp://HOST:PORT"`` of a running Dask scheduler, ``"local"``, or None (default: the
        ``DASK_SCHEDULER_ADDRESS`` environment variable, else no Dask).
    results : path, optional
        JSON-lines file of finished results (module docstring): appended as they arrive; jobs whose
        key it holds are not run again.
    progress : bool
        A progress bar on stderr.
    desc : str
        The bar's label.

    Raises
    ------
    JobsError
        Bad settings, repeated keys, a results file that is not a file, a non-finite result to be
        saved, or Dask missing for a scheduler.
    """
    kind = _executor(workers, scheduler)
    jobs = [(k, tuple(a)) for k, a in jobs]
    texts = [_key_text(k) for k, _ in jobs]
    if len(set(texts)) != len(texts):
        dup = sorted({t for t in texts if texts.count(t) > 1})
        raise JobsError(f"job keys must be distinct; repeated: {', '.join(dup[:5])}")
    path = Path(results) if results is not None else None
    done = _load_done(path) if path is not None else {}
    out: dict[str, Any] = {t: done[t] for t in texts if t in done}
    todo = [(k, a) for (k, a), t in zip(jobs, texts) if t not in out]
    # connected before the results file is opened: a wrong scheduler leaves nothing behind
    dask = _connect(kind, workers) if todo and kind not in ("serial", "processes") else None
    sink = _Sink(path)
    try:
        with _bar(progress, len(jobs), len(out), desc) as bar:
            if not todo:
                pass
            elif kind == "serial":
                for k, a in todo:
                    r = fn(*a)
                    sink.put(k, r)
                    out[_key_text(k)] = r
                    bar.update()
            elif kind == "processes":
                # spawn, not fork: numba's OpenMP threads in this process make fork() unsafe; one thread
                # per worker process, as Dask's nanny sets it (N processes x N BLAS/numba threads on N cores
                # oversubscribe them)
                with _single_threaded_children(), \
                        ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as ex:
                    pending = {ex.submit(fn, *a): k for k, a in todo}
                    try:
                        while pending:
                            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                            for fut in finished:
                                k = pending.pop(fut)
                                r = fut.result()  # a job's error is raised here, as in a serial run
                                sink.put(k, r)
                                out[_key_text(k)] = r
                                bar.update()
                    except BaseException:
                        ex.shutdown(wait=True, cancel_futures=True)  # the others: not started, not waited for
                        raise
            else:
                _run_dask(fn, todo, dask[0], sink, out, bar)
    finally:
        sink.close()
        if dask is not None:
            dask[0].close()
            if dask[1] is not None:
                dask[1].close()
    return {k: out[t] for (k, _), t in zip(jobs, texts)}


#: Thread-count variables set to 1 for the spawned worker processes (Dask's nanny sets the same).
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


@contextlib.contextmanager
def _single_threaded_children():
    """While active, processes started from this one inherit one thread each for BLAS, OpenMP and numba."""
    saved = {k: os.environ.get(k) for k in THREAD_VARS}
    os.environ.update({k: "1" for k in THREAD_VARS})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _connect(kind: str, workers: int):
    """``(client, cluster)``: a Dask client on the scheduler ``kind`` (``"local"``: on a new LocalCluster of
    ``workers`` single-threaded processes, returned to be closed after the client)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise JobsError("a Dask scheduler needs the optional extra: pip install \"ptw-assist[cluster]\"") from None
    if kind == "local":
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                               env={k: "1" for k in THREAD_VARS},  # one thread per worker, numba's too
                               silence_logs=logging.CRITICAL)  # no worker log lines (a heartbeat at shutdown)
        return Client(cluster), cluster
    try:
        return Client(kind, timeout="10s"), None
    except OSError as exc:
        raise JobsError(f"scheduler {kind}: cannot connect ({exc})") from None


def _run_dask(fn, todo, client, sink: _Sink, out: dict, bar) -> None:
    from distributed import as_completed

    keys = [k for k, _ in todo]
    if len({len(a) for _, a in todo}) == 1 and todo[0][1]:  # one call for all: less per-job overhead
        futs = client.map(fn, *zip(*(a for _, a in todo)), pure=False)
    else:
        futs = [client.submit(fn, *a, pure=False) for _, a in todo]
    futures = dict(zip(futs, keys))
    for fut in as_completed(futures):
        k = futures[fut]
        r = fut.result()
        sink.put(k, r)
        out[_key_text(k)] = r
        bar.update()
