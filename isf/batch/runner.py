"""Running a batch: its tasks on Dask (a local cluster of processes, or any running
scheduler) or one after another in this process, each recorded as it ends.

See docs/batch.md for the manifest, the output folder and how it scales.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple, TextIO

from ..exceptions import InvalidInputError
from .keys import KeyedTask, key_tasks
from .manifest import BatchTask, read_manifest, tasks_from_mapping
from .progress import TaskProgress
from .store import BatchFolder
from .worker import TaskOutcome, run_task

__all__ = ["BatchSummary", "SYNCHRONOUS", "TaskFailure", "run_batch"]

SYNCHRONOUS = "synchronous"
"""The ``scheduler`` that runs the tasks one after another in this process, without Dask."""

_SHOWN_FAILURES = 10
"""Failed tasks listed one by one in a summary; the others are counted."""


class TaskFailure(NamedTuple):
    """A failed task: its key, what it planned, and why it failed."""

    key: str
    object: str
    gripper: str
    error: str
    error_kind: str


@dataclass
class BatchSummary:
    """How a batch went.

    Attributes:
        folder: the output folder.
        total: tasks in the manifest (after removing repeated ones).
        skipped: tasks finished by an earlier run on the folder, not run again.
        done: tasks finished now.
        failures: tasks that failed now.
        superseded: tasks of earlier runs no longer in the manifest, whose files were moved to
            ``superseded/``.
        repeated: tasks the manifest lists more than once (run once).
        wall_time: seconds from start to end of this run.
        dashboard: the Dask dashboard's address, if one ran.
    """

    folder: Path
    total: int
    skipped: int = 0
    done: int = 0
    failures: list[TaskFailure] = field(default_factory=list)
    superseded: int = 0
    repeated: int = 0
    wall_time: float = 0.0
    dashboard: str | None = None

    @property
    def failed(self) -> int:
        return len(self.failures)

    @property
    def ok(self) -> bool:
        """True when every task of the manifest is finished."""
        return not self.failures and self.skipped + self.done == self.total

    def format(self) -> str:
        """The summary as lines of text: counts, then the failures and why."""
        lines = [f"{self.total} tasks: {self.skipped + self.done} done ({self.skipped} before "
                 f"this run), {self.failed} failed, in {self.wall_time:.1f} s; output in "
                 f"{self.folder}"]
        if self.repeated:
            lines.append(f"{self.repeated} tasks repeated in the manifest were run once")
        if self.superseded:
            lines.append(f"{self.superseded} tasks of earlier runs are no longer in the manifest: "
                         f"their files moved to {self.folder / 'superseded'}")
        if self.failures:
            kinds = Counter(f.error_kind for f in self.failures)
            lines.append("failed: " + ", ".join(f"{n} {_KIND_TEXT[k]}" for k, n in kinds.items()))
            for f in self.failures[:_SHOWN_FAILURES]:
                lines.append(f"  {f.key} {f.object} x {f.gripper}: {f.error}")
            if self.failed > _SHOWN_FAILURES:
                lines.append(f"  ... and {self.failed - _SHOWN_FAILURES} more (tasks.parquet lists them)")
        return "\n".join(lines)


_KIND_TEXT = {"input": "bad input (file, name or parameter)", "internal": "internal error (a bug)",
              "worker": "worker died"}


def run_batch(
    manifest: str | Path | Mapping[str, Any] | list[BatchTask],
    out: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    retries: int = 1,
    progress: TextIO | None = sys.stderr,
    on_outcome: Callable[[TaskOutcome], None] | None = None,
) -> BatchSummary:
    """Run a batch of plans into the folder ``out``; rerun, it skips the finished tasks.

    Args:
        manifest: a YAML or CSV manifest file, its content as a mapping (``defaults``,
            ``cross``, ``tasks``; paths relative to the working folder) or a list of tasks.
        out: the output folder (created if missing; docs/batch.md describes its files).
        workers: processes of the local Dask cluster (one thread each; default the machine's
            cores); not allowed with ``scheduler``.
        scheduler: the address of a running Dask scheduler (e.g. ``tcp://host:8786``), or
            ``"synchronous"``: the tasks one after another in this process, without Dask.
            None (default): a local cluster of ``workers`` processes.
        retries: times a task is run again when the process running it dies (a running
            scheduler may also run it again by itself: its ``allowed-failures``, default 3).
        progress: where to show the progress and the dashboard's address (None: nowhere).
        on_outcome: called with each task's outcome as it ends (in this process).

    Returns:
        the :class:`BatchSummary`; failed tasks are in it and in ``tasks.parquet``.

    Raises:
        InvalidInputError: a bad manifest, ``workers`` < 1, ``retries`` < 0, or both
            ``workers`` and ``scheduler``.
        OutputFileError: ``out`` cannot be written.
    """
    started = time.perf_counter()
    if workers is not None and scheduler is not None:
        raise InvalidInputError("workers sets the size of a local cluster; a scheduler has its "
                                "own workers: pass one of them")
    if workers is not None and workers < 1:
        raise InvalidInputError(f"workers must be >= 1, got {workers}")
    if retries < 0:
        raise InvalidInputError(f"retries must be >= 0, got {retries}")
    listed = key_tasks(_tasks(manifest))
    keyed = list({k.key: k for k in listed}.values())  # a repeated task runs once
    with BatchFolder(out) as folder:
        summary = BatchSummary(folder.root, len(keyed), repeated=len(listed) - len(keyed))
        summary.superseded = folder.retire_others({k.key for k in keyed})
        todo = [k for k in keyed if not folder.is_finished(k.key)]
        summary.skipped = len(keyed) - len(todo)
        try:
            _run(todo, folder, summary, workers, scheduler, retries, progress, on_outcome)
        finally:
            folder.write_tasks_table(keyed)
            summary.wall_time = time.perf_counter() - started
    return summary


def _run(todo: list[KeyedTask], folder: BatchFolder, summary: BatchSummary, workers, scheduler,
         retries: int, progress: TextIO | None, on_outcome) -> None:
    """Run the tasks ``todo`` and record each as it ends."""
    if not todo:
        return
    if scheduler == SYNCHRONOUS:
        outcomes, slots = _run_here(todo), 1
    else:
        outcomes, slots = _run_on_dask(todo, workers, scheduler, retries, progress, summary)
    bar = TaskProgress(len(todo), slots, progress)
    by_key = {k.key: k for k in todo}
    try:
        for outcome in outcomes:
            record = folder.save(by_key[outcome.key], outcome)
            if outcome.status == "done":
                summary.done += 1
            else:
                summary.failures.append(TaskFailure(outcome.key, record["object"], record["gripper"],
                                                    outcome.error or "", outcome.error_kind or "internal"))
            bar.update(outcome.status == "done")
            if on_outcome is not None:
                on_outcome(outcome)
    finally:
        bar.close()
        outcomes.close()  # ends the Dask client and cluster


def _tasks(manifest) -> list[BatchTask]:
    if isinstance(manifest, (str, Path)):
        return read_manifest(manifest)
    if isinstance(manifest, Mapping):
        return tasks_from_mapping(manifest, Path.cwd())
    tasks = list(manifest)
    if not tasks or not all(isinstance(t, BatchTask) for t in tasks):
        raise InvalidInputError("manifest must be a file, a mapping or a non-empty list of BatchTask")
    return tasks


def _run_here(todo: list[KeyedTask]) -> Iterator[TaskOutcome]:
    for k in todo:
        yield run_task(k)


def _run_on_dask(todo, workers, scheduler, retries, progress, summary):
    """Submit the tasks to Dask; returns (outcomes as they end, worker threads)."""
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError as err:
        raise InvalidInputError(f"isf batch needs Dask ({err.name} is missing): pip install "
                                "'dask[distributed]', or pass scheduler 'synchronous'") from None
    cluster = None
    if scheduler is None:
        dashboard = importlib.util.find_spec("bokeh") is not None
        with dask.config.set({"distributed.scheduler.allowed-failures": 0}):  # retried here
            cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                                   processes=True, dashboard_address=":0" if dashboard else None,
                                   silence_logs=logging.ERROR)
        summary.dashboard = cluster.dashboard_link if dashboard else None
        if progress is not None:
            progress.write(f"isf batch: Dask dashboard at {summary.dashboard}\n" if dashboard else
                           "isf batch: no Dask dashboard (pip install bokeh to have one)\n")
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout="20s")
        except OSError as err:
            raise InvalidInputError(f"cannot reach the Dask scheduler {scheduler}: {err}: start "
                                    "it, or check the address") from None
    slots = sum(client.nthreads().values()) or 1
    return _dask_outcomes(client, cluster, todo, retries), slots


def _dask_outcomes(client, cluster, todo: list[KeyedTask], retries: int) -> Iterator[TaskOutcome]:
    """Each task's outcome as it ends. A task whose worker died is submitted again, up to
    ``retries`` times, then becomes a failed outcome (:func:`run_task` itself never raises)."""
    from distributed import as_completed

    try:
        by_key = {k.key: k for k in todo}
        futures = {client.submit(run_task, k, key=f"isf-batch-{k.key}", pure=False): k.key
                   for k in todo}
        runs = dict.fromkeys(by_key, 1)
        pending = as_completed(futures)
        for future in pending:
            key = futures.pop(future)
            try:
                outcome = future.result()
            except Exception as err:  # the worker died (KilledWorker) or was lost
                if runs[key] <= retries:
                    retry = client.submit(run_task, by_key[key], key=f"isf-batch-{key}-{runs[key]}",
                                          pure=False)
                    runs[key] += 1
                    futures[retry] = key
                    pending.add(retry)
                    continue
                outcome = TaskOutcome(key, "failed", error_kind="worker", error=(
                    f"{type(err).__name__}: {' '.join(str(err).split())} (the task ran {runs[key]} "
                    "time(s); its worker died each time)")[:2000])
            finally:
                future.release()
            yield outcome
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
