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

import numpy as np
from numba import njit

from ..search import kdtree
from ._elements import convex_depth, non_convex_depth, triangle_distance2
from .surface_distance import NEIGHBOURS, estimate
from .voxels import box_clear, distance_below
from ..search.nearest import nearest_point, search_scratch

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


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _transform(poses, e, x, y, z):
    """Point ``(x, y, z)`` of element ``e``'s frame in the object frame."""
    return (poses[e, 0, 0] * x + poses[e, 0, 1] * y + poses[e, 0, 2] * z + poses[e, 0, 3],
            poses[e, 1, 0] * x + poses[e, 1, 1] * y + poses[e, 1, 2] * z + poses[e, 1, 3],
            poses[e, 2, 0] * x + poses[e, 2, 1] * y + poses[e, 2, 2] * z + poses[e, 2, 3])


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _estimate_at(x, y, z, surface, search):
    """:func:`isf.collision.surface_distance.estimate` of the object's surface at ``(x, y, z)``."""
    tree = surface[2]
    return estimate(x, y, z, search[0], search[1], surface[0], surface[1], tree[0], tree[1], tree[2],
                    tree[3], tree[4], tree[5], tree[6], tree[7], search[2], search[3], search[4])


@njit(cache=True, nogil=True, error_model="numpy")
def _planes_and_spheres(poses, obstacles, elements, surface, voxels, search):
    """The obstacle planes' depths and clearance, and which elements need their samples tested.

    Returns ``(depth, where, clearance, deep, apart, clearance_bound, lo, hi, estimates)``: per
    element its depth below the planes and the plane (-1 for none), the planes' clearance; *deep*: its
    box overlaps the object's box (and, for a mesh object, voxels not certainly outside) and its
    bounding sphere may reach inside; *apart*: a non-contact element that may lie nearer to the
    object than the clearance bound (the planes' clearance and the nearest object point from
    every non-contact element's sphere centre plus its radius); the box of its hull (E, 3).
    """
    normals_p, offsets_p = obstacles
    hull, hull_start, sphere, radius, contact = elements[0], elements[1], elements[2], elements[3], elements[4]
    olo, ohi, cover = surface[3], surface[4], surface[5]
    has_voxels, table, vlo, vsize = voxels[0], voxels[1], voxels[3], voxels[4]
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
    return depth, where, clearance, deep, apart, clearance_bound, elo, ehi, estimates


@njit(cache=True, nogil=True, error_model="numpy")
def _patch_centres(poses, act, deep, apart, clearance_bound, elements, patches, surface, voxels, search):
    """The patches of the active elements ``act`` (A,) and their centres' estimates.

    A patch farther from the object's box than its radius (or, for a deep element, whose ball
    lies with :data:`VOXEL_MARGIN` to spare in voxels outside a mesh object) holds no sample
    inside the object; one farther than its radius plus the clearance bound none nearer to it.
    The centres of the other patches of deep elements, and of every element's last vertex, are
    evaluated; so are those of apart elements that may hold samples nearer than an evaluated
    centre of an apart element.

    Returns ``(patch, pk, need, outside_patch, sd, plane, nearest, foot, estimates)``: per patch
    its index, its element's position in ``act``, whether it is evaluated, and the estimate at
    its centre (signed distance, plane point, distance to and index of the nearest object point);
    per active element whether a patch was settled outside without evaluation.
    """
    element_patches, last_patch = elements[9], elements[10]
    samples, patch_start, patch_radius = patches[0], patches[3], patches[5]
    olo, ohi = surface[3], surface[4]
    has_voxels, table, voxel_gaps, vlo, vsize = voxels
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
    return patch, pk, need, outside_patch, sd, plane, nearest, foot, estimates


@njit(cache=True, nogil=True, error_model="numpy")
def _rows(poses, tolerance, act, deep, apart, patch, pk, need, outside_patch, sd, plane, nearest,
          elements, patches, surface):
    """The rows: the samples of the opened patches with their first-order predictions and
    bounds, and the centres of the others.

    A deep element's patch is opened when its lowest prediction (over the box of its offsets)
    less the bound at its radius could change the verdict (below ``-tolerance``) or touching (a
    non-contact element none of whose centres lies inside: below 0), when its lowest prediction
    could be deeper than the deepest centre, or when none of the element's centres or settled
    patches lies outside (it may lie wholly inside); so are the two patches of apart elements
    whose centres lie nearest the object.

    Returns ``(row, rp, pred, lo, hi, seg, last_row)``: per row its sample, its patch (index into
    ``patch``), its prediction and bounds; the rows of active element ``k`` are
    ``seg[k]:seg[k + 1]``, the row of its last vertex is ``last_row[k]``.
    """
    contact, last_patch = elements[4], elements[10]
    offsets, margin, patch_start, patch_size, patch_margin, box_lo, box_hi = (
        patches[1], patches[2], patches[3], patches[4], patches[6], patches[7], patches[8])
    normals = surface[1]
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
    return row, rp, pred, lo, hi, seg, last_row


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _evaluate_row(r, e, poses, row, pred, lo, hi, samples, surface, search):
    """Evaluate row ``r`` (of element ``e``) exactly."""
    s = row[r]
    x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
    pred[r] = lo[r] = hi[r] = _estimate_at(x, y, z, surface, search)[0]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
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


@njit(cache=True, nogil=True, error_model="numpy")
def _refine(poses, tolerance, plane_depth, clearance, act, deep, outside_patch, row, pred, lo, hi, seg,
            elements, patches, surface, search):
    """Evaluate exactly the rows that can change a verdict, the deepest value, whether a
    non-contact element touches, or whether an element lies wholly inside.

    The first round takes each element's :data:`DEEPEST_CANDIDATES` deepest-looking (lowest
    predicted) candidates for the verdict, the value and touching; later rounds all remaining
    verdict candidates of unsettled elements and the value's candidates while the deepest value
    grows. Every round takes all rows that may lie outside an element none of whose rows (nor
    settled patches) lies certainly outside. Returns the number of rows evaluated and, per
    active element, the depth of its deepest evaluated row.
    """
    contact, samples = elements[4], patches[0]
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


@njit(cache=True, nogil=True, error_model="numpy")
def _object_depth(poses, e, box_lo, box_hi, tolerance, elements, probes, interiors, scratch):
    """Deepest object point inside closed element ``e`` (0 for an open one), metres, by
    :func:`isf.collision._elements.convex_depth` or :func:`isf.collision._elements.non_convex_depth`
    of the object points in the grid cells that the box ``[box_lo, box_hi]`` of its hull overlaps
    (every point inside it lies there). ``scratch``: room for all the points, (M, 3)."""
    kind, bounds, planes, plane_start = elements[5], elements[6], elements[7], elements[8]
    points, cell_start, grid_lo, cell, shape = probes
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
    hull_planes, hull_start, field, field_start, field_shape, field_lo, field_h, inner_start, node_start, \
        inner_points, inner_normals, tree_points, order, start, stop, axis, split, left, right = interiors
    a, b, f, n0, n1 = inner_start[e], inner_start[e + 1], field_start[e], node_start[e], node_start[e + 1]
    values = field[f:field_start[e + 1]].reshape((field_shape[e, 0], field_shape[e, 1], field_shape[e, 2]))
    tree = (tree_points[a:b], order[a:b], start[n0:n1], stop[n0:n1], axis[n0:n1], split[n0:n1], left[n0:n1],
            right[n0:n1])
    return non_convex_depth(scratch[:n], poses[e], bounds[e], tolerance,
                            hull_planes[hull_start[e]:hull_start[e + 1]], values, field_lo[e], field_h[e],
                            inner_points[a:b], inner_normals[a:b], tree, min(NEIGHBOURS, b - a))


@njit(cache=True, nogil=True, error_model="numpy")
def _object_depths(poses, tolerance, act, deep, outside_patch, pred, lo, hi, seg, last_row, deepest, depth,
                   where, clearance, box_lo, box_hi, elements, probes, interiors, obstacle):
    """Each deep element's depth into the object: that of its deepest evaluated row or object
    point inside it; when some row lies certainly inside and none (nor a settled patch)
    certainly outside and no object point lies inside it, it lies wholly inside and its last
    vertex tells. Updates ``depth`` and ``where`` (to ``obstacle``); returns the clearance, 0
    when a non-contact element penetrates."""
    contact = elements[4]
    scratch = np.empty((len(probes[0]), 3))
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


@njit(cache=True, nogil=True, error_model="numpy")
def _clearance_candidates(poses, act, apart, row, rp, pk, foot, samples, surface, search):
    """The :data:`CLEARANCE_CANDIDATES` rows of apart elements nearest the object point nearest
    their patch centre (ties: the earlier row): positions (C, 3), elements (C,) and distances to
    the nearest object point (C,)."""
    points = surface[0]
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
    scratch = (search[2], search[3], search[4])
    for j in range(n):
        r = top[j]
        e, s = act[pk[rp[r]]], row[r]
        x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
        candidates[j, 0], candidates[j, 1], candidates[j, 2] = x, y, z
        owner[j] = e
        nearest[j] = np.sqrt(nearest_point(x, y, z, foot[rp[r]], points, surface[2], scratch,
                                             np.inf)[1])
    return candidates, owner, nearest


@njit(cache=True, nogil=True, error_model="numpy")
def reverse_clearance(measured, candidates, owner, poses, triangles, triangle_start, points, tree, probes):
    """The clearance from clearance candidates ``candidates`` (C, 3) of elements ``owner`` (C,)
    with their measured distances to the object ``measured`` (C,), m: the least of those and
    of the exact distances from the ``probes`` object points nearest the best candidate of each
    of two elements (those of the lowest indices among the candidates') to that element's
    triangles (link frame, ``triangles[triangle_start[e]:triangle_start[e + 1]]``), >= 0."""
    order = np.argsort(measured, kind="mergesort")
    best = measured[order[0]]
    first = np.full(len(poses), -1, np.int64)  # each element's best candidate
    for j in order:
        if first[owner[j]] < 0:
            first[owner[j]] = j
    best_d2, nearest = np.empty(probes), np.empty(probes, np.int64)
    stack_node, stack_bound, stack_offset = search_scratch()
    done = 0
    for e in range(len(poses)):
        j = first[e]
        if j < 0 or done == 2:
            continue
        done += 1
        kdtree.k_nearest(candidates[j, 0], candidates[j, 1], candidates[j, 2], best_d2, nearest, tree[0],
                         tree[1], tree[2], tree[3], tree[4], tree[5], tree[6], tree[7], stack_node,
                         stack_bound, stack_offset)
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


@njit(cache=True, nogil=True, error_model="numpy")
def check_elements(T, link_R, link_p, tolerance, obstacles, elements, patches, surface, probes, voxels,
                   interiors):
    """One check of the elements at palm pose ``T`` (4, 4), their links at rotations ``link_R``
    (L, 3, 3) and positions ``link_p`` (L, 3) in the gripper frame (see :mod:`isf.collision.checker` for
    what it computes).

    Args:
        tolerance: penetration tolerated, metres.
        obstacles: ``(normals (P, 3), offsets (P,))`` of the obstacle planes.
        elements: ``(hull, hull_start, sphere, radius, contact, kind, bounds, planes,
            plane_start, element_patches, last_patch, frames)``: hull vertices (H, 3) of element
            ``e`` at ``hull_start[e]:hull_start[e + 1]``; bounding sphere centres (E, 3) and radii
            (E,); contact flags (E,); kind (E,) (0 open, 1 closed convex, 2 closed non-convex);
            link frame boxes (E, 2, 3); convex face planes (F, 4) at
            ``plane_start[e]:plane_start[e + 1]``; patches ``element_patches[e]:element_patches[e + 1]``;
            the patch of the last vertex (E,); the link of each element (E,).
        patches: ``(samples, offsets, margin, patch_start, patch_size, patch_radius,
            patch_margin, box_lo, box_hi)``: the samples of every patch (S, 3) at
            ``patch_start[p]:patch_start[p] + patch_size[p]``, its centre first, link frame; their
            offsets from the centre (S, 3) and prediction bounds (S,) (0 at the centres); per patch
            its radius, the prediction bound at that radius and the box of its offsets (P, 3).
        surface: ``(points, normals, tree, lo, hi, cover, neighbours)``: the object's tangent
            planes and their tree (:attr:`isf.search.nearest.NearestPoints.tree`), its box, the cover (m)
            and the neighbour count of the estimate.
        probes: ``(points, cell_start, lo, cell, shape)``: the object's own points (those tested
            inside elements) in a grid of cubic cells, edge ``cell``, corner ``lo``, ``shape``
            cells: those of cell ``(a, b, c)`` are ``points[cell_start[i]:cell_start[i + 1]]``
            with ``i = (a * shape[1] + b) * shape[2] + c``.
        voxels: ``(present, table, gaps, lo, size)`` of :class:`isf.collision.voxels.SurfaceVoxels`.
        interiors: the non-convex closed elements' hull planes, grids and surfaces (with their
            trees) stacked, each with its start per element (``isf.collision.checker._packed``).

    Returns:
        ``(poses, depth, where, clearance, candidates, owner, nearest, estimates)``: the elements'
        poses (E, 4, 4); each element's depth (E,) and its obstacle (E,) (plane index, P for the
        object, -1 for none); the clearance so far (0, or the obstacle planes'), m; the clearance
        candidates (C, 3) (none when the clearance is 0), their elements (C,) and distances to
        the nearest object point (C,); the number of exact estimates made.
    """
    frames = elements[11]
    poses = np.zeros((len(frames), 4, 4))
    for e in range(len(frames)):
        f = frames[e]
        for i in range(4):
            for j in range(3):
                poses[e, i, j] = T[i, 0] * link_R[f, 0, j] + T[i, 1] * link_R[f, 1, j] + T[i, 2] * link_R[f, 2, j]
            poses[e, i, 3] = T[i, 0] * link_p[f, 0] + T[i, 1] * link_p[f, 1] + T[i, 2] * link_p[f, 2] + T[i, 3]
    stack_node, stack_bound, stack_offset = search_scratch()
    search = (np.empty(surface[6]), np.empty(surface[6], np.int64), stack_node, stack_bound, stack_offset)
    depth, where, clearance, deep, apart, clearance_bound, box_lo, box_hi, estimates = _planes_and_spheres(
        poses, obstacles, elements, surface, voxels, search)
    act = np.flatnonzero(deep | apart)
    none = (np.empty((0, 3)), np.empty(0, np.int64), np.empty(0))
    if len(act) == 0:
        return poses, depth, where, clearance, none[0], none[1], none[2], estimates
    patch, pk, need, outside_patch, sd, plane, nearest, foot, count = _patch_centres(
        poses, act, deep, apart, clearance_bound, elements, patches, surface, voxels, search)
    estimates += count
    row, rp, pred, lo, hi, seg, last_row = _rows(
        poses, tolerance, act, deep, apart, patch, pk, need, outside_patch, sd, plane, nearest, elements,
        patches, surface)
    count, deepest = _refine(poses, tolerance, depth.max(), clearance, act, deep, outside_patch, row, pred,
                             lo, hi, seg, elements, patches, surface, search)
    estimates += count
    clearance = _object_depths(poses, tolerance, act, deep, outside_patch, pred, lo, hi, seg, last_row,
                               deepest, depth, where, clearance, box_lo, box_hi, elements, probes, interiors,
                               len(obstacles[1]))
    if clearance == 0.0:
        return poses, depth, where, clearance, none[0], none[1], none[2], estimates
    candidates, owner, nearest = _clearance_candidates(poses, act, apart, row, rp, pk, foot, patches[0],
                                                       surface, search)
    return poses, depth, where, clearance, candidates, owner, nearest, estimates
