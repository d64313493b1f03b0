"""Run an experiment's runs on Dask (a LocalCluster on every core, or a lab cluster's scheduler) or in this
process, writing each run's row as it finishes: `<out>/runs/<run_id>.parquet`.

Nothing finished is lost to a crash or Ctrl-C (each file is written whole, then renamed into place), and a rerun
of the same spec skips the runs whose file says "done" (failed runs are tried again). One command at a time runs
into a results folder (`out_lock`).
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

from antarium.ant.experiment.spec import Run

RUNS_DIR = "runs"
#: the file in a results folder locked by the command running into it (it holds "pid N on HOST")
LOCK_FILE = ".lock"


def run_path(out: Path, run_id: str) -> Path:
    return Path(out) / RUNS_DIR / f"{run_id}.parquet"


def write_row(out: Path, row: dict) -> Path:
    """Write one run's row as a Parquet file, atomically (a reader never sees half a file)."""
    import pandas as pd

    path = run_path(out, row["run_id"])
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    pd.DataFrame([row]).to_parquet(tmp, engine="pyarrow", index=False)
    os.replace(tmp, path)
    return path


def finished(out: Path, runs: Iterable[Run]) -> set[str]:
    """run_ids of `runs` already done in `out` (their file holds their own row, with status "done")."""
    import pyarrow.parquet as pq

    done = set()
    for run in runs:
        path = run_path(out, run.run_id)
        if path.is_file():
            try:
                row = pq.read_table(path, columns=["run_id", "status"]).to_pylist()[0]
            except Exception:  # an unreadable file is not a finished run: run it again
                continue
            if row == {"run_id": run.run_id, "status": "done"}:   # not another run's row under its name
                done.add(run.run_id)
    return done


@contextlib.contextmanager
def out_lock(out: Path) -> Iterator[None]:
    """Hold `out`'s lock (`LOCK_FILE`) while the block runs: a second command into one results folder would run
    every run the first has not finished yet, again. RuntimeError naming the command that holds it."""
    import fcntl

    with open(Path(out) / LOCK_FILE, "a+") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            holder = f.read().strip() or "a process that has not written its pid yet"
            raise RuntimeError(f"results folder {out} is in use by another experiment ({holder}); wait for it to "
                               "end, or give another --out") from None
        f.truncate(0)
        f.write(f"pid {os.getpid()} on {socket.gethostname()}")
        f.flush()
        try:
            yield
        finally:
            f.truncate(0)


@dataclass
class Progress:
    total: int
    skipped: int = 0
    done: int = 0
    failed: int = 0


def _bar(total: int, skipped: int):
    from tqdm import tqdm

    return tqdm(total=total, initial=skipped, desc="runs", unit="run", dynamic_ncols=True)


def _record(out: Path, row: dict, progress: Progress, bar) -> None:
    write_row(out, row)
    if row["status"] == "done":
        progress.done += 1
    else:
        progress.failed += 1
    if bar is not None:
        bar.set_postfix(done=progress.done + progress.skipped, failed=progress.failed, refresh=False)
        bar.update(1)


def _failed_row(run: Run, exc: BaseException) -> dict:
    """The row of a run whose worker died or could not return it (the run itself never raises)."""
    return {**run.columns(), "status": "failed", "error": f"{type(exc).__name__}: {exc}"}


def run_experiment(runs: list[Run], out: str | Path, scheduler: str | None = None, workers: int | None = None,
                   serial: bool = False, progress_bar: bool = True,
                   on_row: Callable[[dict], None] | None = None, run_timeout_s: float | None = None,
                   task: Callable[[Run], dict] | None = None) -> Progress:
    """Run what is not yet done of `runs`, writing a Parquet row per run into `out/runs/` as each finishes.

    scheduler: a Dask scheduler address (tcp://host:8786) of a lab cluster; otherwise a LocalCluster of `workers`
    processes (default: every core), one thread each; serial: in this process, no Dask.
    on_row: called with each finished row (in this process). run_timeout_s: a run still running that long after
    its worker started it (s; None: no limit; Dask only) is recorded as failed (`RunTimeout`) and its worker
    restarted, so that a run that hangs cannot hold up the sweep. task: what a worker runs per run (default
    `execute.run_task`). Returns the counts.
    """
    if run_timeout_s is not None:
        if not (isinstance(run_timeout_s, int | float) and math.isfinite(run_timeout_s) and run_timeout_s > 0):
            raise ValueError(f"--run-timeout-s must be a finite number of seconds > 0, got {run_timeout_s!r}")
        if serial:
            raise ValueError("--run-timeout-s needs Dask workers (a run in this process cannot be stopped); leave "
                             "out --serial, or --run-timeout-s")
    out = Path(out)
    (out / RUNS_DIR).mkdir(parents=True, exist_ok=True)
    with out_lock(out):
        return _run_pending(runs, out, scheduler, workers, serial, progress_bar, on_row, run_timeout_s, task)


def _run_pending(runs: list[Run], out: Path, scheduler, workers, serial: bool, progress_bar: bool, on_row,
                 run_timeout_s: float | None = None, task=None) -> Progress:
    done = finished(out, runs)
    pending = [r for r in runs if r.run_id not in done]
    progress = Progress(len(runs), skipped=len(runs) - len(pending))
    bar = _bar(len(runs), progress.skipped) if progress_bar else None
    try:
        if serial:
            from antarium.ant.experiment.execute import run_row

            for run in pending:
                row = run_row(run)
                _record(out, row, progress, bar)
                if on_row is not None:
                    on_row(row)
        elif pending:
            _run_dask(pending, out, scheduler, workers, progress, bar, on_row, run_timeout_s, task)
    finally:
        if bar is not None:
            bar.close()
    return progress


#: Dask config for local workers:
#: - Dask's nannies start workers with MALLOC_TRIM_THRESHOLD_=65536 (freed memory goes back to the system at once);
#:   set at all, it fixes glibc's mmap threshold at 128 kB, so every larger array of a run (a frame's cube map,
#:   1.8 MB) is a fresh mmap zeroed page by page: 16x the page faults and 11 % longer runs, measured. Local workers
#:   start without it (a value the user set is inherited).
#: - the workers' statistical profiler (a thread taking the interpreter lock every 10 ms) feeds only the
#:   dashboard, which local clusters do not serve; with a worker on every core, runs took 6 % and 26 % longer
#:   with it than without it in two paired measurements.
WORKER_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                 "distributed.worker.profile.enabled": False}


def local_cluster(n_workers: int):
    """A LocalCluster of `n_workers` processes on loopback, one thread each, with `worker_env` and `WORKER_CONFIG`,
    ignoring Ctrl-C (`execute.dask_setup`: the command stops them)."""
    import dask
    from distributed import LocalCluster

    with dask.config.set(WORKER_CONFIG):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                            dashboard_address=None, silence_logs=40, env=worker_env(n_workers),
                            preload=["antarium.ant.experiment.execute"])


def worker_env(n_workers: int) -> dict[str, str]:
    """The environment of `n_workers` local workers: a software GL driver (llvmpipe) in each rasterises on its
    share of the cores, not with a thread on every core in every worker; no effect on a GPU driver. A value the
    user set is kept."""
    if "LP_NUM_THREADS" in os.environ:
        return {}
    return {"LP_NUM_THREADS": str(max(1, (os.cpu_count() or 1) // n_workers))}


#: how long the command waits for a lab cluster's scheduler to answer (s)
SCHEDULER_TIMEOUT_S = 15
#: how often the main process looks for a Ctrl-C while it waits for the runs' results (s)
INTERRUPT_POLL_S = 0.1


@contextlib.contextmanager
def _interrupt_flag() -> Iterator[threading.Event]:
    """An event set by Ctrl-C (SIGINT) while the block runs, in place of a KeyboardInterrupt: raised at any point
    of Dask's machinery, one can be swallowed (a garbage-collector callback of distributed's printed it and went
    on) and the command waited for workers that Ctrl-C had ended. Outside the main thread no handler can be set:
    the event is then never set."""
    flag = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    previous = signal.signal(signal.SIGINT, lambda signum, frame: flag.set())
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, previous)


class _Watch:
    """When each run started on which worker (`execute.announce_start`'s events, timed on this computer's clock:
    the workers' clocks are never compared with it)."""

    def __init__(self) -> None:
        self.started: dict[str, tuple[float, str]] = {}  # run_id -> (time.monotonic(), worker address)

    def __call__(self, event) -> None:  # the Dask client's thread
        msg = event[1]
        self.started[msg["run_id"]] = (time.monotonic(), msg["worker"])

    def overdue(self, run_ids: Iterable[str], timeout_s: float) -> list[tuple[str, float, str]]:
        """(run_id, seconds running, worker) of the runs among `run_ids` running longer than `timeout_s`."""
        now, late = time.monotonic(), []
        for run_id in run_ids:
            if run_id in self.started:
                t0, worker = self.started[run_id]
                if now - t0 > timeout_s:
                    late.append((run_id, now - t0, worker))
        return late


def _stop_overdue(client, run: Run, running_s: float, worker: str, timeout_s: float) -> dict:
    """The failed row of `run`, overdue on `worker`; the worker is restarted (by its nanny), which ends the run."""
    import sys

    status = client.restart_workers([worker], raise_for_error=False).get(worker, "no answer")
    restarted = "its worker was restarted" if status == "OK" else f"its worker could not be restarted ({status})"
    error = (f"RunTimeout: the run was still running after {running_s:.0f} s on worker {worker} (--run-timeout-s "
             f"{timeout_s:g}); {restarted}")
    if status != "OK":
        print(f"antarium ant experiment: run {run.run_id}: {error}; a worker without a nanny (dask worker "
              "--no-nanny) cannot be restarted: stop it by hand", file=sys.stderr, flush=True)
    return {**run.columns(), "status": "failed", "error": error}


def _run_dask(pending: list[Run], out: Path, scheduler, workers, progress: Progress, bar, on_row,
              run_timeout_s: float | None = None, task=None) -> None:
    """Run `pending` on Dask, recording each row as it comes; a run over `run_timeout_s` is recorded as failed
    and its worker restarted (`_stop_overdue`); Ctrl-C stops waiting within INTERRUPT_POLL_S, closes the client
    and the local cluster and raises KeyboardInterrupt (the rows recorded so far are kept)."""
    from distributed import Client, as_completed

    from antarium.ant.experiment.execute import RUN_STARTED_TOPIC, run_task

    if scheduler:
        cluster = None
        try:
            client = Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s")
        except (OSError, ValueError) as exc:   # nothing answers there (OSError), or not an address (ValueError)
            raise RuntimeError(f"--scheduler {scheduler}: {exc}; start one with `dask scheduler` (it listens on "
                               "tcp://<host>:8786), or leave --scheduler out to run on this machine") from None
    else:
        cluster = local_cluster(workers or os.cpu_count() or 1)
        client = Client(cluster)
    try:
        with _interrupt_flag() as interrupted:
            watch = _Watch()
            if run_timeout_s is not None:
                client.subscribe_topic(RUN_STARTED_TOPIC, watch)
            by_key = {f"run-{r.run_id}": r for r in pending}
            submitted = client.map(task or run_task, pending, key=list(by_key), pure=False, retries=0)
            running = {by_key[f.key].run_id: f for f in submitted}  # not yet recorded
            futures = as_completed(submitted)
            while not futures.is_empty():
                if interrupted.is_set():
                    raise KeyboardInterrupt
                for run_id, running_s, worker in watch.overdue(running, run_timeout_s) if run_timeout_s else ():
                    fut = running.pop(run_id)
                    fut.cancel()  # first: the scheduler forgets it, so the restart does not run it again
                    row = _stop_overdue(client, by_key[fut.key], running_s, worker, run_timeout_s)
                    _record(out, row, progress, bar)
                    if on_row is not None:
                        on_row(row)
                if not futures.has_ready():
                    interrupted.wait(INTERRUPT_POLL_S)
                    continue
                fut = next(futures)
                if running.pop(by_key[fut.key].run_id, None) is None:  # recorded as overdue (now cancelled)
                    continue
                try:
                    row = fut.result()
                except Exception as exc:  # the worker died (e.g. out of memory): record it, go on
                    row = _failed_row(by_key[fut.key], exc)
                _record(out, row, progress, bar)
                if on_row is not None:
                    on_row(row)
                fut.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
