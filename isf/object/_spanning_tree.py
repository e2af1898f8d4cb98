"""Consistent signs over a graph: propagation along a minimum spanning forest.

Orienting triangle windings and point-cloud normals are both the same problem: choose a sign
(+1/-1) per node so that neighbours agree, trusting the most reliable edges first. The signs
spread from one seed per connected component along the minimum spanning forest of the graph
(Hoppe et al. 1992).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

__all__ = ["tree_signs"]


def tree_signs(
    n: int, edges: np.ndarray, weights: np.ndarray, seeds_of: Callable, flip_of: Callable
) -> tuple[np.ndarray, np.ndarray]:
    """Propagate a sign (+1/-1) per node along a minimum spanning forest.

    Args:
        n: number of nodes.
        edges: undirected edges, shape (E, 2).
        weights: positive edge weights, shape (E,).
        seeds_of: ``labels (n,) -> seeds (C,)``, one node per connected component.
        flip_of: ``(children (M,), parents (M,)) -> bool (M,)``, True where the child's sign must
            be the opposite of its parent's.

    Returns:
        (signs (n,) int8 with +1 at every seed, component labels (n,)).
    """
    i, j = np.minimum(edges[:, 0], edges[:, 1]), np.maximum(edges[:, 0], edges[:, 1])
    keep = i != j
    key, first = np.unique(i[keep] * n + j[keep], return_index=True)
    w = weights[keep][first]
    graph = coo_matrix((w, (key // n, key % n)), shape=(n, n)).tocsr()
    n_comp, labels = connected_components(graph, directed=False)
    seeds = np.asarray(seeds_of(labels), dtype=np.int64)
    tree = minimum_spanning_tree(graph).tocoo()
    # A virtual root (node n) joined to every seed turns the forest into one tree.
    rows = np.concatenate([tree.row, np.full(n_comp, n)])
    cols = np.concatenate([tree.col, seeds])
    forest = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    order, parent = breadth_first_order(forest, n, directed=False, return_predecessors=True)
    order = order[1:]
    parent = parent[:n].copy()
    parent[seeds] = -1
    nonseed = order[parent[order] >= 0]
    flips = np.zeros(n, dtype=bool)
    flips[nonseed] = flip_of(nonseed, parent[nonseed])
    sign = [1] * n
    par, flp = parent.tolist(), flips.tolist()
    for v in order.tolist():
        p = par[v]
        if p >= 0:
            sign[v] = -sign[p] if flp[v] else sign[p]
    return np.asarray(sign, dtype=np.int8), labels
