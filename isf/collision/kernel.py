"""The compiled body of a collision check: culling, patches, predictions, refinement, depths.

:func:`check_elements` runs, in one call per check, everything :mod:`isf.collision.checker` describes
up to the exact clearance measurements: the obstacle planes, the culling of elements and
patches (object box, voxels, bounding spheres), the tangent-plane estimate at the patch
centres, the first-order predictions with their trust bounds, the refinement rounds, each
element's depth summaries, the object points inside its convex elements and the clearance
candidates. Its arrays are prepared once per checker (``isf.collision.checker._packed``).

Conventions: ``poses`` (E, 4, 4) place the elements in the object frame; the *active*
elements are those whose samples are tested; a *row* is one sample of an opened patch, or the
centre of a patch that stays closed, in patch order, and holds the bounds ``[lo, hi]`` of its
signed distance around its prediction (equal to it once evaluated exactly); an active
element's rows are contiguous.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..compiled.kernels import kernel
from ..search import kdtree
from ..search.kdtree import KDTree, SearchScratch
from ..search.nearest import SearchArrays, nearest_point, search_scratch
from ._elements import convex_depth, non_convex_depth, triangle_distance2
from .surface_distance import NEIGHBOURS, estimate
from .voxels import VoxelArrays, box_clear, distance_below

# The first-order prediction of the signed distance at a sample from its patch centre is trusted
# to within PREDICTION_ERROR + PREDICTION_SLOPE * (the distance to the centre).
PREDICTION_ERROR = 1e-4  # m
PREDICTION_SLOPE = 0.5
DEEPEST_CANDIDATES = 8  # samples evaluated exactly to find an element's deepest one
CLEARANCE_CANDIDATES = 48  # nearest-looking samples whose object distance is measured
DEPTH_RESOLUTION = 5e-5  # deeper-looking samples than the deepest evaluated get evaluated, m
CULL_MARGIN = 5e-4  # an element whose bounding sphere is this far outside the object is outside, m
VOXEL_MARGIN = 2e-3  # a box this far inside voxels outside a mesh object is outside it, m
ROUNDS = 3  # refinement rounds at most

__all__ = ["Elements", "Interiors", "Obstacles", "Patches", "Probes", "Surface", "VoxelArrays",
           "check_elements", "reverse_clearance"]


class Obstacles(NamedTuple):
    """The obstacle planes, P of them, object frame: ``n . x >= offset`` is free."""

    normals: np.ndarray
    """Unit normals, (P, 3) float64."""
    offsets: np.ndarray
    """Offsets along the normals, (P,) float64, m."""


class Elements(NamedTuple):
    """The gripper's geometry elements, E of them, link frames, stacked."""

    hull: np.ndarray
    """Hull vertices, (H, 3) float64, m; element ``e``'s are ``hull_start[e]:hull_start[e + 1]``."""
    hull_start: np.ndarray
    """(E + 1,) int64."""
    sphere: np.ndarray
    """Bounding sphere centres, (E, 3) float64, m."""
    radius: np.ndarray
    """Bounding sphere radii, (E,) float64, m."""
    contact: np.ndarray
    """Whether each element carries a contact surface, (E,) bool."""
    kind: np.ndarray
    """0 open, 1 closed convex, 2 closed non-convex, (E,) int64."""
    bounds: np.ndarray
    """Link-frame boxes ``[lo, hi]``, (E, 2, 3) float64, m."""
    planes: np.ndarray
    """Convex elements' face planes ``[n, n . x]``, (F, 4) float64; element ``e``'s are
    ``plane_start[e]:plane_start[e + 1]``."""
    plane_start: np.ndarray
    """(E + 1,) int64."""
    element_patches: np.ndarray
    """Element ``e``'s patches are ``element_patches[e]:element_patches[e + 1]``, (E + 1,) int64."""
    last_patch: np.ndarray
    """The patch of each element's last vertex, (E,) int64."""
    frames: np.ndarray
    """The link of each element (index into the checked links), (E,) int64."""


class Patches(NamedTuple):
    """The elements' surface samples grouped in patches, S samples and P patches, link frames:
    patch ``p``'s samples are ``patch_start[p]:patch_start[p] + patch_size[p]``, centre first."""

    samples: np.ndarray
    """(S, 3) float64, m."""
    offsets: np.ndarray
    """Each sample's offset from its patch centre, (S, 3) float64, m."""
    margin: np.ndarray
    """Each sample's prediction bound (0 at the centres), (S,) float64, m."""
    patch_start: np.ndarray
    """(P,) int64."""
    patch_size: np.ndarray
    """(P,) int64."""
    patch_radius: np.ndarray
    """The largest offset of each patch, (P,) float64, m."""
    patch_margin: np.ndarray
    """The prediction bound at that radius, (P,) float64, m."""
    box_lo: np.ndarray
    """The low corner of the box of each patch's offsets, (P, 3) float64, m."""
    box_hi: np.ndarray
    """Its high corner, (P, 3) float64, m."""


class Surface(NamedTuple):
    """The object's tangent planes (:class:`isf.collision.surface_distance.TangentPlanes`), N
    points."""

    points: np.ndarray
    """(N, 3) float64, m."""
    normals: np.ndarray
    """Outward unit normals, (N, 3) float64."""
    tree: SearchArrays
    """Their search (:attr:`isf.search.nearest.NearestPoints.tree`)."""
    lo: np.ndarray
    """The low corner of the object's box, (3,) float64, m."""
    hi: np.ndarray
    """Its high corner, (3,) float64, m."""
    cover: float
    """Distance from the object's surface to its nearest point, at most, m."""
    neighbours: int
    """The tangent planes of an estimate (:data:`isf.collision.surface_distance.NEIGHBOURS`, at
    most N)."""


class Probes(NamedTuple):
    """The object's own points (those tested inside elements), M of them, in a grid of cubic
    cells: those of cell ``(a, b, c)`` are ``points[cell_start[i]:cell_start[i + 1]]`` with
    ``i = (a * shape[1] + b) * shape[2] + c``."""

    points: np.ndarray
    """(M, 3) float64, m, by cell."""
    cell_start: np.ndarray
    """(cells + 1,) int64."""
    lo: np.ndarray
    """The grid's corner, (3,) float64, m."""
    cell: float
    """The cells' edge, m."""
    shape: np.ndarray
    """Cells along each axis, (3,) int64."""


class Interiors(NamedTuple):
    """The insides of the closed non-convex elements, stacked (empty parts for the others), link
    frames: hull planes, signed-distance grids and surfaces with their k-d trees."""

    hull_planes: np.ndarray
    """Hull face planes ``[n, n . x]``, (G, 4) float64; element ``e``'s are
    ``hull_start[e]:hull_start[e + 1]``."""
    hull_start: np.ndarray
    """(E + 1,) int64."""
    field: np.ndarray
    """Grid values raveled, float64, m; element ``e``'s are ``field_start[e]:field_start[e + 1]``."""
    field_start: np.ndarray
    """(E + 1,) int64."""
    field_shape: np.ndarray
    """Each grid's shape, (E, 3) int64."""
    field_lo: np.ndarray
    """Each grid's first node, (E, 3) float64, m."""
    field_h: np.ndarray
    """Each grid's spacing, (E,) float64, m."""
    inner_start: np.ndarray
    """Element ``e``'s surface points (and tree positions) are ``inner_start[e]:inner_start[e +
    1]``, (E + 1,) int64."""
    node_start: np.ndarray
    """Element ``e``'s tree nodes are ``node_start[e]:node_start[e + 1]``, (E + 1,) int64."""
    inner_points: np.ndarray
    """Surface points, (N, 3) float64, m."""
    inner_normals: np.ndarray
    """Their outward unit normals, (N, 3) float64."""
    tree: KDTree
    """The surfaces' k-d trees stacked (indices within each element's part)."""


class _Scratch(NamedTuple):
    """Scratch of the tangent-plane estimates of one check."""

    best_d2: np.ndarray
    """Squared distances of the nearest points, (neighbours,) float64, m^2."""
    best: np.ndarray
    """Their indices, (neighbours,) int64."""
    stack: SearchScratch
    """The tree search's stack."""


class _Culling(NamedTuple):
    """What :func:`_planes_and_spheres` finds, E elements."""

    depth: np.ndarray
    """Each element's depth below the obstacle planes, (E,) float64, m."""
    where: np.ndarray
    """The plane it lies deepest below (-1 for none), (E,) int64."""
    clearance: float
    """The obstacle planes' clearance, m."""
    deep: np.ndarray
    """Whether the element may reach inside the object, (E,) bool."""
    apart: np.ndarray
    """Whether the non-contact element may lie nearer the object than ``clearance_bound``, (E,)
    bool."""
    clearance_bound: float
    """An upper bound of the clearance, m."""
    box_lo: np.ndarray
    """The low corners of the boxes of the elements' hulls, object frame, (E, 3) float64, m."""
    box_hi: np.ndarray
    """Their high corners, (E, 3) float64, m."""
    estimates: int
    """Exact estimates made."""


class _Centres(NamedTuple):
    """The patches of the active elements (:func:`_patch_centres`), P of them, A active elements."""

    patch: np.ndarray
    """Each patch's index, (P,) int64."""
    pk: np.ndarray
    """Its element's position among the active ones, (P,) int64."""
    need: np.ndarray
    """Whether its centre is evaluated, (P,) bool."""
    outside_patch: np.ndarray
    """Per active element, whether a patch was settled outside without evaluation, (A,) bool."""
    sd: np.ndarray
    """The signed distance estimate at each evaluated centre, (P,) float64, m."""
    plane: np.ndarray
    """The object point whose tangent plane sets it, (P,) int64."""
    nearest: np.ndarray
    """The distance to the nearest object point, (P,) float64, m."""
    foot: np.ndarray
    """That point's index, (P,) int64."""
    estimates: int
    """Exact estimates made."""


class _Rows(NamedTuple):
    """The rows of one check (:func:`_rows`), R rows and A active elements."""

    row: np.ndarray
    """Each row's sample, (R,) int64."""
    rp: np.ndarray
    """Its patch (index into :attr:`_Centres.patch`), (R,) int64."""
    pred: np.ndarray
    """Its predicted signed distance (exact once evaluated), (R,) float64, m."""
    lo: np.ndarray
    """The lower bound of its signed distance, (R,) float64, m."""
    hi: np.ndarray
    """The upper bound, (R,) float64, m."""
    seg: np.ndarray
    """Active element ``k``'s rows are ``seg[k]:seg[k + 1]``, (A + 1,) int64."""
    last_row: np.ndarray
    """The row of each active element's last vertex, (A,) int64."""


@kernel(inline=True)
def _transform(poses, e, x, y, z):
    """Point ``(x, y, z)`` of element ``e``'s frame in the object frame."""
    return (poses[e, 0, 0] * x + poses[e, 0, 1] * y + poses[e, 0, 2] * z + poses[e, 0, 3],
            poses[e, 1, 0] * x + poses[e, 1, 1] * y + poses[e, 1, 2] * z + poses[e, 1, 3],
            poses[e, 2, 0] * x + poses[e, 2, 1] * y + poses[e, 2, 2] * z + poses[e, 2, 3])


@kernel(inline=True)
def _estimate_at(x, y, z, surface, search):
    """:func:`isf.collision.surface_distance.estimate` of the object's surface at ``(x, y, z)``
    (``search``: a :class:`_Scratch`)."""
    return estimate(x, y, z, search.best_d2, search.best, surface.points, surface.normals,
                    surface.tree.kd, search.stack)


@kernel
def _planes_and_spheres(poses, obstacles, elements, surface, voxels, search):
    """The obstacle planes' depths and clearance, and which elements need their samples tested.

    Returns the :class:`_Culling`: per element its depth below the planes and the plane (-1 for
    none), the planes' clearance; *deep*: its box overlaps the object's box (and, for a mesh
    object, voxels not certainly outside) and its bounding sphere may reach inside; *apart*: a
    non-contact element that may lie nearer to the object than the clearance bound (the planes'
    clearance and the nearest object point from every non-contact element's sphere centre plus
    its radius); the box of its hull.
    """
    normals_p, offsets_p = obstacles.normals, obstacles.offsets
    hull, hull_start, sphere = elements.hull, elements.hull_start, elements.sphere
    radius, contact = elements.radius, elements.contact
    olo, ohi, cover = surface.lo, surface.hi, surface.cover
    has_voxels, table, vlo, vsize = voxels.present, voxels.table, voxels.lo, voxels.size
    n_el = len(poses)
    depth, where = np.zeros(n_el), np.full(n_el, -1, np.int64)
    world = np.empty((len(hull), 3))
    elo, ehi = np.full((n_el, 3), np.inf), np.full((n_el, 3), -np.inf)
    for e in range(n_el):
        for h in range(hull_start[e], hull_start[e + 1]):
            world[h, 0], world[h, 1], world[h, 2] = _transform(poses, e, hull[h, 0], hull[h, 1], hull[h, 2])
            for d in range(3):
                elo[e, d] = min(elo[e, d], world[h, d])
                ehi[e, d] = max(ehi[e, d], world[h, d])
    clearance = np.inf
    for p in range(len(offsets_p)):  # a linear height is least at a hull vertex: exact
        lowest = np.inf
        for e in range(n_el):
            h_e = np.inf
            for h in range(hull_start[e], hull_start[e + 1]):
                h_e = min(h_e, world[h, 0] * normals_p[p, 0] + world[h, 1] * normals_p[p, 1]
                          + world[h, 2] * normals_p[p, 2] - offsets_p[p])
            lowest = min(lowest, h_e)
            if -h_e > depth[e]:
                depth[e], where[e] = -h_e, p
        clearance = min(clearance, max(lowest, 0.0))
    # bounding spheres: the signed distance of the centre less the radius bounds the element's;
    # the distance to the nearest object point plus the radius bounds its clearance
    near = np.zeros(n_el, np.bool_)
    lower = np.full(n_el, np.inf)
    clearance_bound = clearance
    estimates = 0
    for e in range(n_el):
        near[e] = (ehi[e, 0] >= olo[0] and ehi[e, 1] >= olo[1] and ehi[e, 2] >= olo[2]
                   and elo[e, 0] <= ohi[0] and elo[e, 1] <= ohi[1] and elo[e, 2] <= ohi[2])
        if near[e] and has_voxels:
            near[e] = not box_clear(table, vlo, vsize, elo[e, 0] - VOXEL_MARGIN, elo[e, 1] - VOXEL_MARGIN,
                                    elo[e, 2] - VOXEL_MARGIN, ehi[e, 0] + VOXEL_MARGIN,
                                    ehi[e, 1] + VOXEL_MARGIN, ehi[e, 2] + VOXEL_MARGIN)
        if near[e] or not contact[e]:
            x, y, z = _transform(poses, e, sphere[e, 0], sphere[e, 1], sphere[e, 2])
            sd, _, nearest, _ = _estimate_at(x, y, z, surface, search)
            estimates += 1
            lower[e] = min(sd, nearest - cover) - radius[e]
            if not contact[e]:
                clearance_bound = min(clearance_bound, nearest + radius[e])
    deep, apart = np.zeros(n_el, np.bool_), np.zeros(n_el, np.bool_)
    for e in range(n_el):
        deep[e] = near[e] and lower[e] < CULL_MARGIN
        apart[e] = not contact[e] and lower[e] < clearance_bound
    return _Culling(depth, where, clearance, deep, apart, clearance_bound, elo, ehi, estimates)


@kernel
def _patch_centres(poses, act, culling, elements, patches, surface, voxels, search):
    """The patches of the active elements ``act`` (A,) and their centres' estimates.

    A patch farther from the object's box than its radius (or, for a deep element, whose ball
    lies with :data:`VOXEL_MARGIN` to spare in voxels outside a mesh object) holds no sample
    inside the object; one farther than its radius plus the clearance bound none nearer to it.
    The centres of the other patches of deep elements, and of every element's last vertex, are
    evaluated; so are those of apart elements that may hold samples nearer than an evaluated
    centre of an apart element.

    Returns the :class:`_Centres`: per patch its index, its element's position in ``act``,
    whether it is evaluated, and the estimate at its centre (signed distance, plane point,
    distance to and index of the nearest object point); per active element whether a patch was
    settled outside without evaluation.
    """
    deep, apart, clearance_bound = culling.deep, culling.apart, culling.clearance_bound
    element_patches, last_patch = elements.element_patches, elements.last_patch
    samples, patch_start, patch_radius = patches.samples, patches.patch_start, patches.patch_radius
    olo, ohi = surface.lo, surface.hi
    has_voxels, table, voxel_gaps, vlo, vsize = (voxels.present, voxels.table, voxels.gaps,
                                                  voxels.lo, voxels.size)
    n_patch = 0
    for k in range(len(act)):
        n_patch += element_patches[act[k] + 1] - element_patches[act[k]]
    patch, pk = np.empty(n_patch, np.int64), np.empty(n_patch, np.int64)
    centre = np.empty((n_patch, 3))
    gap, need, outside = np.empty(n_patch), np.zeros(n_patch, np.bool_), np.zeros(n_patch, np.bool_)
    i = 0
    for k in range(len(act)):
        e = act[k]
        for p in range(element_patches[e], element_patches[e + 1]):
            patch[i], pk[i] = p, k
            s = patch_start[p]
            x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
            centre[i, 0], centre[i, 1], centre[i, 2] = x, y, z
            gx = max(max(olo[0] - x, x - ohi[0]), 0.0)
            gy = max(max(olo[1] - y, y - ohi[1]), 0.0)
            gz = max(max(olo[2] - z, z - ohi[2]), 0.0)
            gap[i] = np.sqrt(gx * gx + gy * gy + gz * gz)
            rho = patch_radius[p]
            outside[i] = gap[i] > rho
            if has_voxels:
                if deep[e] and not outside[i]:
                    reach = rho + VOXEL_MARGIN
                    outside[i] = box_clear(table, vlo, vsize, x - reach, y - reach, z - reach,
                                           x + reach, y + reach, z + reach)
                gap[i] = max(gap[i], distance_below(voxel_gaps, vlo, vsize, x, y, z))
            need[i] = (deep[e] and not outside[i]) or p == last_patch[e]
            i += 1
    sd, plane = np.empty(n_patch), np.empty(n_patch, np.int64)
    nearest, foot = np.empty(n_patch), np.empty(n_patch, np.int64)
    estimates = 0
    bound = clearance_bound
    for i in range(n_patch):
        if need[i]:
            sd[i], plane[i], nearest[i], foot[i] = _estimate_at(centre[i, 0], centre[i, 1], centre[i, 2],
                                                                surface, search)
            estimates += 1
            if apart[act[pk[i]]]:
                bound = min(bound, nearest[i])
    for i in range(n_patch):  # for the clearance
        if not need[i] and apart[act[pk[i]]] and gap[i] - patch_radius[patch[i]] < bound:
            need[i] = True
            sd[i], plane[i], nearest[i], foot[i] = _estimate_at(centre[i, 0], centre[i, 1], centre[i, 2],
                                                                surface, search)
            estimates += 1
    outside_patch = np.zeros(len(act), np.bool_)
    for i in range(n_patch):
        if not need[i] and outside[i]:
            outside_patch[pk[i]] = True
    return _Centres(patch, pk, need, outside_patch, sd, plane, nearest, foot, estimates)


@kernel
def _rows(poses, tolerance, act, culling, centres, elements, patches, surface):
    """The rows: the samples of the opened patches with their first-order predictions and
    bounds, and the centres of the others.

    A deep element's patch is opened when its lowest prediction (over the box of its offsets)
    less the bound at its radius could change the verdict (below ``-tolerance``) or touching (a
    non-contact element none of whose centres lies inside: below 0), when its lowest prediction
    could be deeper than the deepest centre, or when none of the element's centres or settled
    patches lies outside (it may lie wholly inside); so are the two patches of apart elements
    whose centres lie nearest the object.

    Returns the :class:`_Rows`: per row its sample, its patch (index into ``centres.patch``),
    its prediction and bounds; the rows of active element ``k`` are ``seg[k]:seg[k + 1]``, the
    row of its last vertex is ``last_row[k]``.
    """
    deep, apart = culling.deep, culling.apart
    patch, pk, need, outside_patch = centres.patch, centres.pk, centres.need, centres.outside_patch
    sd, plane, nearest = centres.sd, centres.plane, centres.nearest
    contact, last_patch = elements.contact, elements.last_patch
    offsets, margin, patch_start, patch_size = (patches.offsets, patches.margin, patches.patch_start,
                                                patches.patch_size)
    patch_margin, box_lo, box_hi = patches.patch_margin, patches.box_lo, patches.box_hi
    normals = surface.normals
    n_act, n_patch = len(act), len(patch)
    centre_depth = np.full(n_act, -np.inf)
    outside_centre = np.zeros(n_act, np.bool_)
    for i in range(n_patch):
        if need[i]:
            centre_depth[pk[i]] = max(centre_depth[pk[i]], -sd[i])
            outside_centre[pk[i]] |= sd[i] >= 0.0
    m = np.empty((n_patch, 3))  # the gradient in the link frame: R^T n
    opened = np.zeros(n_patch, np.bool_)
    first, second = -1, -1  # the patches of apart elements nearest the object
    for i in range(n_patch):
        if not need[i]:
            continue
        k, p = pk[i], patch[i]
        e = act[k]
        n = plane[i]
        for j in range(3):
            m[i, j] = poses[e, 0, j] * normals[n, 0] + poses[e, 1, j] * normals[n, 1] + poses[e, 2, j] * normals[n, 2]
        low = sd[i] + (min(box_lo[p, 0] * m[i, 0], box_hi[p, 0] * m[i, 0])
                       + min(box_lo[p, 1] * m[i, 1], box_hi[p, 1] * m[i, 1])
                       + min(box_lo[p, 2] * m[i, 2], box_hi[p, 2] * m[i, 2]))
        low_bound = low - patch_margin[p]
        if deep[e]:
            opened[i] = (low_bound < -tolerance
                         or low < -(max(centre_depth[k], 0.0) + DEPTH_RESOLUTION)
                         or (not contact[e] and not centre_depth[k] > 0.0 and low_bound < 0.0)
                         or not (outside_centre[k] or outside_patch[k]))
        if apart[e]:
            if first < 0 or nearest[i] < nearest[first]:
                first, second = i, first
            elif second < 0 or nearest[i] < nearest[second]:
                second = i
    for i in (first, second):
        if i >= 0:
            opened[i] = True
    n_rows = 0
    for i in range(n_patch):
        if need[i]:
            n_rows += patch_size[patch[i]] if opened[i] else 1
    row, rp = np.empty(n_rows, np.int64), np.empty(n_rows, np.int64)
    pred, lo, hi = np.empty(n_rows), np.empty(n_rows), np.empty(n_rows)
    seg, last_row = np.zeros(n_act + 1, np.int64), np.empty(n_act, np.int64)
    r = 0
    for i in range(n_patch):
        if not need[i]:
            continue
        k, p = pk[i], patch[i]
        if p == last_patch[act[k]]:
            last_row[k] = r
        for s in range(patch_start[p], patch_start[p] + (patch_size[p] if opened[i] else 1)):
            row[r], rp[r] = s, i
            pred[r] = sd[i] + (offsets[s, 0] * m[i, 0] + offsets[s, 1] * m[i, 1] + offsets[s, 2] * m[i, 2])
            bound = margin[s] if opened[i] else 0.0
            lo[r], hi[r] = pred[r] - bound, pred[r] + bound
            r += 1
        seg[k + 1] = r
    return _Rows(row, rp, pred, lo, hi, seg, last_row)


@kernel(inline=True)
def _evaluate_row(r, e, poses, row, pred, lo, hi, samples, surface, search):
    """Evaluate row ``r`` (of element ``e``) exactly."""
    s = row[r]
    x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
    sd, _, _, _ = _estimate_at(x, y, z, surface, search)
    pred[r] = lo[r] = hi[r] = sd


@kernel(inline=True)
def _offer(top, n, r, pred):
    """Offer row ``r`` to ``top[:n]``, the rows with the lowest ``pred`` so far in order (ties: the
    earlier row), at most ``len(top)``; returns the new count."""
    if n == len(top) and pred[r] >= pred[top[n - 1]]:
        return n
    j = min(n, len(top) - 1)
    while j > 0 and pred[top[j - 1]] > pred[r]:
        top[j] = top[j - 1]
        j -= 1
    top[j] = r
    return min(n + 1, len(top))


@kernel
def _refine(poses, tolerance, act, culling, centres, rows, elements, patches, surface, search):
    """Evaluate exactly the rows that can change a verdict, the deepest value, whether a
    non-contact element touches, or whether an element lies wholly inside.

    The first round takes each element's :data:`DEEPEST_CANDIDATES` deepest-looking (lowest
    predicted) candidates for the verdict, the value and touching; later rounds all remaining
    verdict candidates of unsettled elements and the value's candidates while the deepest value
    grows. Every round takes all rows that may lie outside an element none of whose rows (nor
    settled patches) lies certainly outside. Returns the number of rows evaluated and, per
    active element, the depth of its deepest evaluated row. Updates the bounds of ``rows``.
    """
    plane_depth, clearance, deep = culling.depth.max(), culling.clearance, culling.deep
    outside_patch = centres.outside_patch
    row, pred, lo, hi, seg = rows.row, rows.pred, rows.lo, rows.hi, rows.seg
    contact, samples = elements.contact, patches.samples
    n_act = len(act)
    deepest, now = np.zeros(n_act), np.zeros(n_act)
    for k in range(n_act):
        for r in range(seg[k], seg[k + 1]):
            if lo[r] == hi[r]:
                deepest[k] = max(deepest[k], -pred[r])
    improving = np.ones(n_act, np.bool_)
    want = np.zeros(len(row), np.bool_)
    top_value = np.empty(DEEPEST_CANDIDATES, np.int64)
    top_verdict, top_touch = np.empty(DEEPEST_CANDIDATES, np.int64), np.empty(DEEPEST_CANDIDATES, np.int64)
    estimates = 0
    for round_ in range(ROUNDS):
        overall = plane_depth
        for k in range(n_act):
            overall = max(overall, deepest[k])
        unknown_any = False
        count = 0
        for k in range(n_act):
            e = act[k]
            now[k] = deepest[k]
            if not deep[e]:
                continue
            outside, touching, unknown = outside_patch[k], False, False
            for r in range(seg[k], seg[k + 1]):
                touching |= lo[r] == hi[r] and pred[r] < 0.0  # an evaluated row inside
                outside |= lo[r] >= 0.0  # a row certainly outside
                unknown |= lo[r] != hi[r]
            if not unknown:
                continue
            unknown_any = True
            n_value = n_verdict = n_touch = 0
            for r in range(seg[k], seg[k + 1]):
                if lo[r] == hi[r]:
                    continue
                verdict = deepest[k] <= tolerance and -lo[r] > tolerance
                if -pred[r] > overall + DEPTH_RESOLUTION and improving[k]:
                    n_value = _offer(top_value, n_value, r, pred)
                if round_ == 0:
                    if verdict:
                        n_verdict = _offer(top_verdict, n_verdict, r, pred)
                    if clearance > 0.0 and not contact[e] and not touching and lo[r] < 0.0:
                        n_touch = _offer(top_touch, n_touch, r, pred)
                want[r] = (not outside and hi[r] >= 0.0) or (round_ > 0 and verdict)  # wholly inside?
            for j in range(n_value):
                want[top_value[j]] = True
            for j in range(n_verdict):
                want[top_verdict[j]] = True
            for j in range(n_touch):
                want[top_touch[j]] = True
            for r in range(seg[k], seg[k + 1]):
                if want[r]:
                    want[r] = False
                    _evaluate_row(r, e, poses, row, pred, lo, hi, samples, surface, search)
                    now[k] = max(now[k], -pred[r])
                    count += 1
        if not unknown_any or count == 0:
            break
        estimates += count
        for k in range(n_act):
            improving[k] = now[k] > deepest[k]
            deepest[k] = now[k]
    return estimates, deepest


@kernel
def _object_depth(poses, e, box_lo, box_hi, tolerance, elements, probes, interiors, scratch):
    """Deepest object point inside closed element ``e`` (0 for an open one), metres, by
    :func:`isf.collision._elements.convex_depth` or :func:`isf.collision._elements.non_convex_depth`
    of the object points in the grid cells that the box ``[box_lo, box_hi]`` of its hull overlaps
    (every point inside it lies there). ``scratch``: room for all the points, (M, 3)."""
    kind, bounds, planes, plane_start = (elements.kind, elements.bounds, elements.planes,
                                         elements.plane_start)
    points, cell_start, grid_lo, cell, shape = (probes.points, probes.cell_start, probes.lo,
                                                probes.cell, probes.shape)
    if kind[e] == 0:
        return 0.0
    first, last = np.empty(3, np.int64), np.empty(3, np.int64)
    for d in range(3):
        first[d] = min(max(int(np.floor((box_lo[d] - 1e-9 - grid_lo[d]) / cell)), 0), shape[d] - 1)
        last[d] = min(max(int(np.floor((box_hi[d] + 1e-9 - grid_lo[d]) / cell)), 0), shape[d] - 1)
    n = 0
    for a in range(first[0], last[0] + 1):
        for b in range(first[1], last[1] + 1):
            base = (a * shape[1] + b) * shape[2]
            for i in range(cell_start[base + first[2]], cell_start[base + last[2] + 1]):
                scratch[n, 0], scratch[n, 1], scratch[n, 2] = points[i, 0], points[i, 1], points[i, 2]
                n += 1
    if kind[e] == 1:
        return convex_depth(scratch[:n], poses[e], bounds[e], planes[plane_start[e]:plane_start[e + 1]])
    a, b = interiors.inner_start[e], interiors.inner_start[e + 1]
    n0, n1 = interiors.node_start[e], interiors.node_start[e + 1]
    f0, f1 = interiors.field_start[e], interiors.field_start[e + 1]
    shape_e = interiors.field_shape[e]
    values = interiors.field[f0:f1].reshape((shape_e[0], shape_e[1], shape_e[2]))
    t = interiors.tree
    tree = KDTree(t.points[a:b], t.order[a:b], t.start[n0:n1], t.stop[n0:n1], t.axis[n0:n1],
                  t.split[n0:n1], t.left[n0:n1], t.right[n0:n1])
    hull_planes = interiors.hull_planes[interiors.hull_start[e]:interiors.hull_start[e + 1]]
    return non_convex_depth(scratch[:n], poses[e], bounds[e], tolerance, hull_planes, values,
                            interiors.field_lo[e], interiors.field_h[e], interiors.inner_points[a:b],
                            interiors.inner_normals[a:b], tree, min(NEIGHBOURS, b - a))


@kernel
def _object_depths(poses, tolerance, act, culling, centres, rows, deepest, elements, probes,
                   interiors, obstacle):
    """Each deep element's depth into the object: that of its deepest evaluated row (``deepest``,
    per active element) or object point inside it; when some row lies certainly inside and none
    (nor a settled patch) certainly outside and no object point lies inside it, it lies wholly
    inside and its last vertex tells. Updates ``culling.depth`` and ``culling.where`` (to
    ``obstacle``); returns the clearance, 0 when a non-contact element penetrates."""
    deep, depth, where, clearance = culling.deep, culling.depth, culling.where, culling.clearance
    box_lo, box_hi = culling.box_lo, culling.box_hi
    outside_patch = centres.outside_patch
    pred, lo, hi, seg, last_row = rows.pred, rows.lo, rows.hi, rows.seg, rows.last_row
    contact = elements.contact
    scratch = np.empty((len(probes.points), 3))
    for k in range(len(act)):
        e = act[k]
        if not deep[e]:
            continue
        inside_any, outside_any = False, outside_patch[k]
        for r in range(seg[k], seg[k + 1]):
            inside_any |= (lo[r] == hi[r] and pred[r] < 0.0) or hi[r] < 0.0
            outside_any |= lo[r] >= 0.0
        inner = _object_depth(poses, e, box_lo[e], box_hi[e], tolerance, elements, probes, interiors, scratch)
        if inside_any and not outside_any and inner == 0.0:
            d = max(0.0, -pred[last_row[k]])
        else:
            d = max(deepest[k], inner)
        if d > depth[e]:
            depth[e], where[e] = d, obstacle
        if d > 0.0 and not contact[e]:
            clearance = 0.0
    return clearance


@kernel
def _clearance_candidates(poses, act, apart, rows, centres, samples, surface, search):
    """The :data:`CLEARANCE_CANDIDATES` rows of apart elements nearest the object point nearest
    their patch centre (ties: the earlier row): positions (C, 3), elements (C,) and distances to
    the nearest object point (C,)."""
    row, rp, pk, foot = rows.row, rows.rp, centres.pk, centres.foot
    points = surface.points
    top, far = np.empty(CLEARANCE_CANDIDATES, np.int64), np.empty(CLEARANCE_CANDIDATES)
    n = 0
    for r in range(len(row)):
        e = act[pk[rp[r]]]
        if not apart[e]:
            continue
        s, f = row[r], foot[rp[r]]
        x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
        d = np.sqrt(kdtree.squared_distance(points, f, x, y, z))
        if n == CLEARANCE_CANDIDATES and d >= far[n - 1]:
            continue
        j = min(n, CLEARANCE_CANDIDATES - 1)
        while j > 0 and far[j - 1] > d:
            top[j], far[j] = top[j - 1], far[j - 1]
            j -= 1
        top[j], far[j] = r, d
        n = min(n + 1, CLEARANCE_CANDIDATES)
    candidates, owner, nearest = np.empty((n, 3)), np.empty(n, np.int64), np.empty(n)
    for j in range(n):
        r = top[j]
        e, s = act[pk[rp[r]]], row[r]
        x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
        candidates[j, 0], candidates[j, 1], candidates[j, 2] = x, y, z
        owner[j] = e
        _, d2 = nearest_point(x, y, z, foot[rp[r]], points, surface.tree, search.stack, np.inf)
        nearest[j] = np.sqrt(d2)
    return candidates, owner, nearest


@kernel
def reverse_clearance(measured, candidates, owner, poses, triangles, triangle_start, points, tree,
                      probes):
    """The clearance from clearance candidates ``candidates`` (C, 3) of elements ``owner`` (C,)
    with their measured distances to the object ``measured`` (C,), m: the least of those and
    of the exact distances from the ``probes`` object points nearest the best candidate of each
    of two elements (those of the lowest indices among the candidates') to that element's
    triangles (link frame, ``triangles[triangle_start[e]:triangle_start[e + 1]]``), >= 0.
    ``points``, ``tree``: the object's points and their search
    (:attr:`isf.search.nearest.NearestPoints.tree`)."""
    best = np.inf
    first = np.full(len(poses), -1, np.int64)  # each element's best candidate (the first if tied)
    for j in range(len(measured)):
        best = min(best, measured[j])
        if first[owner[j]] < 0 or measured[j] < measured[first[owner[j]]]:
            first[owner[j]] = j
    best_d2, nearest = np.empty(probes), np.empty(probes, np.int64)
    stack = search_scratch()
    done = 0
    for e in range(len(poses)):
        j = first[e]
        if j < 0 or done == 2:
            continue
        done += 1
        kdtree.k_nearest(candidates[j, 0], candidates[j, 1], candidates[j, 2], best_d2, nearest,
                         tree.kd, stack)
        for i in range(probes):
            o = nearest[i]
            x, y, z = points[o, 0] - poses[e, 0, 3], points[o, 1] - poses[e, 1, 3], points[o, 2] - poses[e, 2, 3]
            a = x * poses[e, 0, 0] + y * poses[e, 1, 0] + z * poses[e, 2, 0]
            b = x * poses[e, 0, 1] + y * poses[e, 1, 1] + z * poses[e, 2, 1]
            c = x * poses[e, 0, 2] + y * poses[e, 1, 2] + z * poses[e, 2, 2]
            d2 = np.inf
            for f in range(triangle_start[e], triangle_start[e + 1]):
                d2 = min(d2, triangle_distance2(a, b, c, triangles, f))
            best = min(best, np.sqrt(d2))
    return max(best, 0.0)


@kernel
def check_elements(T, link_R, link_p, tolerance, obstacles, elements, patches, surface, probes, voxels,
                   interiors):
    """One check of the elements at palm pose ``T`` (4, 4), their links at rotations ``link_R``
    (L, 3, 3) and positions ``link_p`` (L, 3) in the gripper frame (see :mod:`isf.collision.checker`
    for what it computes).

    Args:
        tolerance: penetration tolerated, metres.
        obstacles: the obstacle planes (:class:`Obstacles`).
        elements: the geometry elements (:class:`Elements`).
        patches: their samples in patches (:class:`Patches`).
        surface: the object's tangent planes (:class:`Surface`).
        probes: the object's own points in a grid (:class:`Probes`).
        voxels: :func:`isf.collision.voxels.kernel_arrays` of the object's voxels.
        interiors: the non-convex closed elements' insides (:class:`Interiors`).

    Returns:
        ``(poses, depth, where, clearance, candidates, owner, nearest, estimates)``: the elements'
        poses (E, 4, 4); each element's depth (E,) and its obstacle (E,) (plane index, P for the
        object, -1 for none); the clearance so far (0, or the obstacle planes'), m; the clearance
        candidates (C, 3) (none when the clearance is 0), their elements (C,) and distances to
        the nearest object point (C,); the number of exact estimates made.
    """
    frames = elements.frames
    poses = np.zeros((len(frames), 4, 4))
    for e in range(len(frames)):
        f = frames[e]
        for i in range(4):
            for j in range(3):
                poses[e, i, j] = (T[i, 0] * link_R[f, 0, j] + T[i, 1] * link_R[f, 1, j]
                                  + T[i, 2] * link_R[f, 2, j])
            poses[e, i, 3] = (T[i, 0] * link_p[f, 0] + T[i, 1] * link_p[f, 1]
                              + T[i, 2] * link_p[f, 2] + T[i, 3])
    search = _Scratch(np.empty(surface.neighbours), np.empty(surface.neighbours, np.int64),
                      search_scratch())
    culling = _planes_and_spheres(poses, obstacles, elements, surface, voxels, search)
    estimates = culling.estimates
    act = np.flatnonzero(culling.deep | culling.apart)
    no_points, no_owner, no_nearest = np.empty((0, 3)), np.empty(0, np.int64), np.empty(0)
    if len(act) == 0:
        return (poses, culling.depth, culling.where, culling.clearance, no_points, no_owner,
                no_nearest, estimates)
    centres = _patch_centres(poses, act, culling, elements, patches, surface, voxels, search)
    estimates += centres.estimates
    rows = _rows(poses, tolerance, act, culling, centres, elements, patches, surface)
    count, deepest = _refine(poses, tolerance, act, culling, centres, rows, elements, patches,
                             surface, search)
    estimates += count
    clearance = _object_depths(poses, tolerance, act, culling, centres, rows, deepest, elements,
                               probes, interiors, len(obstacles.offsets))
    if clearance == 0.0:
        return (poses, culling.depth, culling.where, clearance, no_points, no_owner, no_nearest,
                estimates)
    candidates, owner, nearest = _clearance_candidates(poses, act, culling.apart, rows, centres,
                                                       patches.samples, surface, search)
    return poses, culling.depth, culling.where, clearance, candidates, owner, nearest, estimates
