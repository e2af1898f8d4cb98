"""Rows of many fits stored back to back: per-fit sums and means without Python loops."""

from __future__ import annotations

import numpy as np

__all__ = ["Segments", "run_starts"]


class Segments:
    """Consecutive groups of rows, one group per fit (every group non-empty).

    Args:
        ids: group of each row, shape (K,), non-decreasing integers ``0 .. B-1`` with
            every group present.
    """

    def __init__(self, ids: np.ndarray):
        self.ids = np.asarray(ids, dtype=np.intp)
        self.counts = np.bincount(self.ids)
        self.starts = np.zeros(len(self.counts), dtype=np.intp)
        np.cumsum(self.counts[:-1], out=self.starts[1:])
        if np.any(self.counts == 0):
            raise ValueError("every segment must hold at least one row")

    @classmethod
    def single(cls, n_rows: int) -> Segments:
        """One group of ``n_rows`` rows."""
        return cls(np.zeros(n_rows, dtype=np.intp))

    @classmethod
    def runs(cls, *keys: np.ndarray) -> Segments:
        """One group per run of consecutive rows with equal keys (each key (K,); a row starts a
        new group when any key differs from the row before)."""
        return cls(np.cumsum(run_starts(*keys)) - 1)

    @classmethod
    def from_counts(cls, counts: np.ndarray) -> Segments:
        """Groups of the given (positive) sizes, shape (B,)."""
        return cls(np.repeat(np.arange(len(counts)), counts))

    def __len__(self) -> int:
        return len(self.counts)

    def sum(self, values: np.ndarray) -> np.ndarray:
        """Per-group sums of ``values`` (K, ...) -> (B, ...)."""
        return np.add.reduceat(values, self.starts, axis=0)

    def mean(self, values: np.ndarray) -> np.ndarray:
        """Per-group means of ``values`` (K, ...) -> (B, ...)."""
        total = self.sum(values)
        return total / self.counts.reshape((-1,) + (1,) * (total.ndim - 1))

    def slices(self) -> list[slice]:
        """The rows of each group, as slices."""
        return [slice(int(a), int(a + n)) for a, n in zip(self.starts, self.counts)]


def run_starts(*keys: np.ndarray) -> np.ndarray:
    """Rows (K,) that start a run of equal keys: the first row and every row where a key changes."""
    first = np.zeros(len(keys[0]), dtype=bool)
    first[:1] = True
    for key in keys:
        first[1:] |= key[1:] != key[:-1]
    return first
