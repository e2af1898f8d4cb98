"""What runs a batch task, in a Dask worker process or in the calling process.

:func:`run_task` plans one :class:`~isf.batch.keys.KeyedTask` and returns a
:class:`TaskOutcome`; it never raises for a failing task: the error is recorded in the outcome,
so one bad file or one error inside isf stops nothing else. Grippers and objects are loaded
in the process from their source (a name, a path or a spec: nothing loaded crosses between
processes) and kept for later tasks of the same process in :data:`SOURCES`, keyed by source and
SHA-256; the compiled kernels are loaded once per process, before its first task.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
import warnings
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

from .keys import KeyedTask

__all__ = ["SOURCES", "SourceCache", "TaskOutcome", "run_task"]


@dataclass
class TaskOutcome:
    """What a task gave: its plan, or its error, with timings (seconds) and provenance.

    Attributes:
        key: the task key.
        status: ``"done"`` or ``"failed"``.
        plan_text: the plan file's text (:func:`isf.planning.plan_json.plan_json_text`), or
            None; :attr:`plan` is its content.
        error: ``"ErrorClass: message"`` of a failed task, or None.
        error_kind: ``"input"`` (an :class:`isf.ISFError`: a bad file, name or parameter),
            ``"internal"`` (any other exception: a bug) or ``"worker"`` (the process running it
            died), or None.
        warnings: isf's warnings during the task, one line each.
        load_time: loading the gripper and the object (0 when both were kept from an earlier
            task of the process).
        warm_time: loading the compiled kernels (the process's first task only).
        plan_time: the plan (:attr:`isf.PlanStats.total_time`).
        task_time: the whole task in the worker, from its start to its return.
        provenance: where and with what it ran: host, pid, python, isf version, start time,
            and the process's peak memory after the task (``max_rss_mb``).
    """

    key: str
    status: str
    plan_text: str | None = None
    error: str | None = None
    error_kind: str | None = None
    warnings: list[str] = field(default_factory=list)
    load_time: float = 0.0
    warm_time: float = 0.0
    plan_time: float = 0.0
    task_time: float = 0.0
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def plan(self) -> dict | None:
        """The plan file's content (:func:`isf.planning.plan_json.plan_to_dict`), or None."""
        return None if self.plan_text is None else json.loads(self.plan_text)


class SourceCache:
    """The grippers and objects a process has loaded, the ``capacity`` latest used of each kind.

    Keyed by what defines them (source, SHA-256 of its file, units, scale), so a file changed
    on disk is loaded again.
    """

    def __init__(self, capacity: int = 8):
        self.capacity = capacity
        self._items: dict[str, OrderedDict] = {"gripper": OrderedDict(), "object": OrderedDict()}
        self.loads = 0

    def get(self, kind: str, key: Hashable, load: Callable[[], Any]) -> Any:
        """The ``kind`` item of ``key``, from ``load()`` on first use."""
        items = self._items[kind]
        if key in items:
            items.move_to_end(key)
            return items[key]
        value = load()
        self.loads += 1
        items[key] = value
        while len(items) > self.capacity:
            items.popitem(last=False)
        return value

    def clear(self) -> None:
        for items in self._items.values():
            items.clear()


SOURCES = SourceCache()
"""This process's loaded grippers and objects (a Dask worker process keeps them between tasks)."""

_warmed = False


def run_task(keyed: KeyedTask) -> TaskOutcome:
    """Plan one task in this process; an error becomes a failed :class:`TaskOutcome`."""
    from .. import __version__
    from ..exceptions import ISFError, ISFWarning

    started = time.perf_counter()
    outcome = TaskOutcome(keyed.key, "failed", provenance={
        "host": socket.gethostname(), "pid": os.getpid(), "python": sys.version.split()[0],
        "isf": __version__, "started_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    })
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ISFWarning)
            outcome.warm_time = _warm_once()
            _plan(keyed, outcome)
        outcome.warnings = [" ".join(str(w.message).split()) for w in caught
                            if issubclass(w.category, ISFWarning)]
        outcome.status = "done"
    except Exception as err:  # every failure is recorded; the batch goes on
        if isinstance(err.__context__, KeyboardInterrupt):  # Ctrl-C inside a compiled kernel
            raise
        outcome.error = f"{type(err).__name__}: {' '.join(str(err).split())}"[:2000]
        outcome.error_kind = "input" if isinstance(err, ISFError) else "internal"
    outcome.task_time = time.perf_counter() - started
    outcome.provenance["max_rss_mb"] = _max_rss_mb()
    return outcome


def _max_rss_mb() -> float | None:
    """The process's peak resident memory so far, MB (None where the system does not say)."""
    try:
        import resource
    except ImportError:  # not on Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return round(peak / (1 << 20 if sys.platform == "darwin" else 1 << 10), 1)


def _warm_once() -> float:
    """Load (or compile) the kernels once per process; the seconds it took."""
    global _warmed
    if _warmed:
        return 0.0
    from ..warming import warm_up

    seconds = warm_up()
    _warmed = True
    return seconds


def _plan(keyed: KeyedTask, outcome: TaskOutcome) -> None:
    from ..collision.checker import Plane
    from ..config import FitConfig, config_from_text
    from ..gripper.bundled import bundled_grippers
    from ..gripper.loading import load_gripper
    from ..object.specs import open_object
    from ..planning.plan_json import Provenance, plan_json_text
    from ..planning.planner import plan
    from ..repair.clearance import RepairConfig
    from ..samplers import get_sampler

    task = keyed.task
    loading = time.perf_counter()
    gripper_source = bundled_grippers().get(task.gripper, task.gripper)
    gripper = SOURCES.get("gripper", (str(gripper_source), keyed.gripper_sha256),
                          lambda: load_gripper(gripper_source))
    obstacles = []
    if task.scene is not None:
        obj = SOURCES.get("object", ("scene", task.scene, keyed.object_sha256, task.intrinsics,
                                     task.camera_pose, task.depth_scale, str(task.table)),
                          lambda: _load_scene(task))
    else:
        obj = SOURCES.get("object", (task.object, keyed.object_sha256, task.units, task.scale),
                          lambda: open_object(task.object, units=task.units, scale=task.scale))
        if task.table is not None:
            obstacles.append(Plane.table(float(task.table)))
    outcome.load_time = time.perf_counter() - loading
    config = config_from_text(FitConfig, {k: str(v) for k, v in task.fit.items()})
    repair = False if task.repair is None else (
        config_from_text(RepairConfig, {k: str(v) for k, v in task.repair.items()})
        if task.repair else True)
    result = plan(gripper, obj, samples=task.samples,
                  sampler=get_sampler(task.sampler, **task.sampler_params), seed=task.seed,
                  config=config, obstacles=obstacles, repair_collisions=repair, rank=task.rank,
                  quality=task.quality_config())
    outcome.plan_time = result.stats.total_time
    file = task.scene if task.scene is not None else task.object
    provenance = Provenance(object_file=None if file.startswith(("shape:", "asset:")) else file,
                            units=task.units, scale=task.scale,
                            parameters={"batch_task": keyed.key, **task.to_dict()})
    outcome.plan_text = plan_json_text(result, top=task.top, provenance=provenance)


def _load_scene(task):
    from ..scene import load_scene

    return load_scene(task.scene, intrinsics=task.intrinsics, T_scene_camera=task.camera_pose,
                      depth_scale=task.depth_scale, table=task.table)
