"""Grasp datasets at scale: ``isf batch`` runs many plans on Dask, resumably, into Parquet.

:func:`run_batch` runs the tasks of a manifest (:func:`read_manifest`) and writes their grasps,
tasks table and plan files into a folder; :func:`load_dataset` reads them back. See
docs/batch.md.
"""

from __future__ import annotations

from .dataset import GRASP_SCHEMA, TASK_SCHEMA, BatchDataset, load_dataset
from .keys import KeyedTask, key_tasks
from .manifest import BatchTask, read_manifest
from .runner import SYNCHRONOUS, BatchSummary, TaskFailure, run_batch
from .worker import TaskOutcome, run_task

__all__ = ["BatchDataset", "BatchSummary", "BatchTask", "GRASP_SCHEMA", "KeyedTask", "SYNCHRONOUS",
           "TASK_SCHEMA", "TaskFailure", "TaskOutcome", "key_tasks", "load_dataset",
           "read_manifest", "run_batch", "run_task"]
