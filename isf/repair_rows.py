"""Compiled pieces of the collision repair's clearance rows (:mod:`isf.clearance`).

* :func:`deepest_rows`: the rows a repair step uses, the most violated ones of each geometry
  element;
* :func:`undecided`: which rows whose violation is only bounded may still be among them, or
  be the most violated row of all (the others need not be computed).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["deepest_rows", "undecided"]


@njit(cache=True, nogil=True, error_model="numpy")
def deepest_rows(violation, element, n_elements, activation, max_rows):
    """Rows within ``activation`` of their floor, at most ``max_rows`` per element.

    Args:
        violation: ``floor - height`` of every row candidate, (M,), metres.
        element: its geometry element, (M,) integers in ``[0, n_elements)``.
        n_elements: number of elements.
        activation: a row with ``violation > -activation`` is a candidate, metres.
        max_rows: candidates kept per element (the most violated ones).

    Returns:
        indices of the kept rows (K,), by element, then most violated first, then by index.
    """
    n_kept = np.zeros(n_elements, np.int64)
    kept = np.empty((n_elements, max_rows), np.int64)  # per element, most violated first
    for i in range(len(violation)):
        v = violation[i]
        if not v > -activation:
            continue
        e = element[i]
        n = n_kept[e]
        if n == max_rows and not v > violation[kept[e, n - 1]]:
            continue
        slot = min(n, max_rows - 1)  # insert after the rows at least as violated (earlier index)
        while slot > 0 and violation[kept[e, slot - 1]] < v:
            kept[e, slot] = kept[e, slot - 1]
            slot -= 1
        kept[e, slot] = i
        n_kept[e] = min(n + 1, max_rows)
    out = np.empty(n_kept.sum(), np.int64)
    n = 0
    for e in range(n_elements):
        out[n:n + n_kept[e]] = kept[e, :n_kept[e]]
        n += n_kept[e]
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def undecided(bound, bound_element, violation, element, n_elements, activation, max_rows, slack):
    """Which rows of unknown violation may still be used, given rows whose violation is known.

    A row is decided (unused) when its violation, at most ``bound``, is below the ``max_rows``
    known ones of its element, or is at most ``-activation`` and below some known one (so it is
    neither a row :func:`deepest_rows` keeps nor the largest violation).

    Args:
        bound: upper bounds of the unknown violations, (U,), metres.
        bound_element: their elements, (U,).
        violation, element: the known violations (K,) and their elements (K,).
        n_elements, activation, max_rows: as for :func:`deepest_rows`.
        slack: rounding allowance on ``bound``, metres.

    Returns:
        mask (U,) of the rows still undecided.
    """
    top = np.full((n_elements, max_rows), -np.inf)  # per element, the largest known, descending
    largest = -np.inf
    for i in range(len(violation)):
        v, e = violation[i], element[i]
        largest = max(largest, v)
        if v > top[e, max_rows - 1]:
            slot = max_rows - 1
            while slot > 0 and top[e, slot - 1] < v:
                top[e, slot] = top[e, slot - 1]
                slot -= 1
            top[e, slot] = v
    out = np.empty(len(bound), np.bool_)
    for i in range(len(bound)):
        b = bound[i] + slack
        out[i] = not (b < top[bound_element[i], max_rows - 1] or (b <= -activation and b < largest))
    return out
