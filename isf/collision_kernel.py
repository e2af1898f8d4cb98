"""The compiled body of a collision check: culling, patches, predictions, refinement, depths.

:func:`check_elements` runs, in one call per check, everything :mod:`isf.collision` describes
up to the exact clearance measurements: the obstacle planes, the culling of elements and
patches (object box, voxels, bounding spheres), the tangent-plane estimate at the patch
centres, the first-order predictions with their trust bounds, the refinement rounds, each
element's depth summaries, the object points inside its convex elements and the clearance
candidates. Its arrays are prepared once per checker (:func:`isf.collision._packed`).

Conventions: ``poses`` (E, 4, 4) place the elements in the object frame; the *active*
elements are those whose samples are tested; a *row* is one sample of an opened patch, or the
centre of a patch that stays closed, in patch order, and holds the bounds ``[lo, hi]`` of its
signed distance around its prediction (equal to it once evaluated exactly); an active
element's rows are contiguous.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .collision_elements import convex_depth
from .collision_surface import estimate
from .collision_voxels import box_clear, distance_below
from .nearest import search_scratch

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


@njit(cache=True, error_model="numpy", inline="always")
def _transform(poses, e, x, y, z):
    """Point ``(x, y, z)`` of element ``e``'s frame in the object frame."""
    return (poses[e, 0, 0] * x + poses[e, 0, 1] * y + poses[e, 0, 2] * z + poses[e, 0, 3],
            poses[e, 1, 0] * x + poses[e, 1, 1] * y + poses[e, 1, 2] * z + poses[e, 1, 3],
            poses[e, 2, 0] * x + poses[e, 2, 1] * y + poses[e, 2, 2] * z + poses[e, 2, 3])


@njit(cache=True, error_model="numpy", inline="always")
def _estimate_at(x, y, z, surface, search):
    """:func:`isf.collision_surface.estimate` of the object's surface at ``(x, y, z)``."""
    tree = surface[2]
    return estimate(x, y, z, search[0], search[1], surface[0], surface[1], tree[0], tree[1], tree[2],
                    tree[3], tree[4], tree[5], tree[6], tree[7], search[2], search[3], search[4])


@njit(cache=True, error_model="numpy")
def _planes_and_spheres(poses, obstacles, elements, surface, voxels, search):
    """The obstacle planes' depths and clearance, and which elements need their samples tested.

    Returns ``(depth, where, clearance, deep, apart, clearance_bound, estimates)``: per element
    its depth below the planes and the plane (-1 for none), the planes' clearance; *deep*: its
    box overlaps the object's box (and, for a mesh object, voxels not certainly outside) and its
    bounding sphere may reach inside; *apart*: a non-contact element that may lie nearer to the
    object than the clearance bound (the planes' clearance and the nearest object point from
    every non-contact element's sphere centre plus its radius).
    """
    normals_p, offsets_p = obstacles
    hull, hull_start, sphere, radius, contact = elements[0], elements[1], elements[2], elements[3], elements[4]
    olo, ohi, cover = surface[5], surface[6], surface[7]
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
    return depth, where, clearance, deep, apart, clearance_bound, estimates


@njit(cache=True, error_model="numpy")
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
    olo, ohi = surface[5], surface[6]
    has_voxels, table, steps, vlo, vsize = voxels
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
                gap[i] = max(gap[i], distance_below(steps, vlo, vsize, x, y, z))
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy", inline="always")
def _evaluate_row(r, e, poses, row, pred, lo, hi, samples, surface, search):
    """Evaluate row ``r`` (of element ``e``) exactly."""
    s = row[r]
    x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
    pred[r] = lo[r] = hi[r] = _estimate_at(x, y, z, surface, search)[0]


@njit(cache=True, error_model="numpy")
def _deepest_looking(mask, pred, seg, want):
    """Mark in ``want`` the :data:`DEEPEST_CANDIDATES` rows of ``mask`` with the lowest ``pred``
    (ties: the earlier row) of each element (rows ``seg[k]:seg[k + 1]``)."""
    top = np.empty(DEEPEST_CANDIDATES, np.int64)
    for k in range(len(seg) - 1):
        n = 0
        for r in range(seg[k], seg[k + 1]):
            if not mask[r] or (n == DEEPEST_CANDIDATES and pred[r] >= pred[top[n - 1]]):
                continue
            j = min(n, DEEPEST_CANDIDATES - 1)
            while j > 0 and pred[top[j - 1]] > pred[r]:
                top[j] = top[j - 1]
                j -= 1
            top[j] = r
            n = min(n + 1, DEEPEST_CANDIDATES)
        for j in range(n):
            want[top[j]] = True


@njit(cache=True, error_model="numpy")
def _deepest_known(pred, lo, hi, seg, out):
    """Per element: the depth of its deepest exactly evaluated row (``lo == hi``), >= 0."""
    for k in range(len(seg) - 1):
        d = 0.0
        for r in range(seg[k], seg[k + 1]):
            if lo[r] == hi[r] and -pred[r] > d:
                d = -pred[r]
        out[k] = d


@njit(cache=True, error_model="numpy")
def _refine(poses, tolerance, plane_depth, clearance, act, deep, outside_patch, row, pred, lo, hi, seg,
           elements, patches, surface, search):
    """Evaluate exactly the rows that can change a verdict, the deepest value, whether a
    non-contact element touches, or whether an element lies wholly inside.

    The first round takes each element's deepest-looking candidates for the verdict, the value
    and touching; later rounds all remaining verdict candidates of unsettled elements and the
    value's candidates while the deepest value grows. Returns the number of rows evaluated and,
    per active element, the depth of its deepest evaluated row.
    """
    contact, samples = elements[4], patches[0]
    n_act, n_rows = len(act), len(row)
    deepest, now = np.empty(n_act), np.empty(n_act)
    _deepest_known(pred, lo, hi, seg, deepest)
    improving = np.ones(n_act, np.bool_)
    outside, touching = np.zeros(n_act, np.bool_), np.zeros(n_act, np.bool_)
    value, verdict, touch = np.zeros(n_rows, np.bool_), np.zeros(n_rows, np.bool_), np.zeros(n_rows, np.bool_)
    want = np.zeros(n_rows, np.bool_)
    estimates = 0
    for round_ in range(ROUNDS):
        overall = plane_depth
        unknown_any = False
        for k in range(n_act):
            overall = max(overall, deepest[k])
            outside[k], touching[k] = outside_patch[k], False
            for r in range(seg[k], seg[k + 1]):
                touching[k] |= lo[r] == hi[r] and pred[r] < 0.0  # an evaluated row inside
                outside[k] |= lo[r] >= 0.0  # a row certainly outside
        for k in range(n_act):
            e = act[k]
            for r in range(seg[k], seg[k + 1]):
                unknown = deep[e] and lo[r] != hi[r]
                unknown_any |= unknown
                verdict[r] = unknown and deepest[k] <= tolerance and -lo[r] > tolerance
                value[r] = unknown and -pred[r] > overall + DEPTH_RESOLUTION and improving[k]
                touch[r] = (round_ == 0 and clearance > 0.0 and unknown and not contact[e]
                            and not touching[k] and lo[r] < 0.0)
                want[r] = (unknown and not outside[k] and hi[r] >= 0.0  # wholly inside?
                           or round_ > 0 and verdict[r])
        if not unknown_any:
            break
        _deepest_looking(value, pred, seg, want)
        if round_ == 0:
            _deepest_looking(verdict, pred, seg, want)
            _deepest_looking(touch, pred, seg, want)
        count = 0
        for k in range(n_act):
            for r in range(seg[k], seg[k + 1]):
                if want[r]:
                    _evaluate_row(r, act[k], poses, row, pred, lo, hi, samples, surface, search)
                    count += 1
        estimates += count
        if count == 0:
            break
        _deepest_known(pred, lo, hi, seg, now)
        for k in range(n_act):
            improving[k] = now[k] > deepest[k]
            deepest[k] = now[k]
    return estimates, deepest


@njit(cache=True, error_model="numpy")
def _summaries(poses, act, deep, outside_patch, pred, lo, hi, seg, last_row, deepest, elements, surface):
    """Per active element ``[deep, inside_any, outside_any, deepest, last vertex's value, convex
    object depth]`` (A, 6): some row certainly inside, some row (or settled patch) certainly
    outside, the deepest evaluated row, the estimate at its last vertex and the deepest object
    point inside it when it is closed and convex."""
    kind, bounds, planes, plane_start = elements[5], elements[6], elements[7], elements[8]
    ordered, ordered_x = surface[3], surface[4]
    summary = np.zeros((len(act), 6))
    for k in range(len(act)):
        e = act[k]
        if not deep[e]:
            continue
        inside_any, outside_any = False, outside_patch[k]
        for r in range(seg[k], seg[k + 1]):
            inside_any |= (lo[r] == hi[r] and pred[r] < 0.0) or hi[r] < 0.0
            outside_any |= lo[r] >= 0.0
        summary[k, 0], summary[k, 1], summary[k, 2] = 1.0, inside_any, outside_any
        summary[k, 3], summary[k, 4] = deepest[k], pred[last_row[k]]
        if kind[e] == 1:  # the object points within the x span of its box (a bound of its hull's)
            reach = 1e-9
            for j in range(3):
                reach += abs(poses[e, 0, j]) * max(abs(bounds[e, 0, j]), abs(bounds[e, 1, j]))
            first = np.searchsorted(ordered_x, poses[e, 0, 3] - reach)
            last = np.searchsorted(ordered_x, poses[e, 0, 3] + reach, side="right")
            summary[k, 5] = convex_depth(ordered[first:last], poses[e], bounds[e],
                                         planes[plane_start[e]:plane_start[e + 1]])
    return summary


@njit(cache=True, error_model="numpy")
def _clearance_candidates(poses, act, apart, row, rp, pk, foot, samples, points):
    """The :data:`CLEARANCE_CANDIDATES` rows of apart elements nearest the object point nearest
    their patch centre (ties: the earlier row): positions (C, 3), elements (C,) and those object
    points (C,)."""
    n = 0
    for r in range(len(row)):
        n += apart[act[pk[rp[r]]]]
    far, place, free_row = np.empty(n), np.empty((n, 3)), np.empty(n, np.int64)
    j = 0
    for r in range(len(row)):
        e = act[pk[rp[r]]]
        if not apart[e]:
            continue
        s, f = row[r], foot[rp[r]]
        x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
        place[j, 0], place[j, 1], place[j, 2] = x, y, z
        far[j] = np.sqrt((x - points[f, 0]) ** 2 + (y - points[f, 1]) ** 2 + (z - points[f, 2]) ** 2)
        free_row[j] = r
        j += 1
    take = np.argsort(far, kind="mergesort")[:CLEARANCE_CANDIDATES]
    candidates = np.empty((len(take), 3))
    owner, guess = np.empty(len(take), np.int64), np.empty(len(take), np.int64)
    for j in range(len(take)):
        t = take[j]
        candidates[j, 0], candidates[j, 1], candidates[j, 2] = place[t, 0], place[t, 1], place[t, 2]
        i = rp[free_row[t]]
        owner[j], guess[j] = act[pk[i]], foot[i]
    return candidates, owner, guess


@njit(cache=True, error_model="numpy")
def check_elements(poses, tolerance, obstacles, elements, patches, surface, voxels):
    """One check of the posed elements (see :mod:`isf.collision` for what it computes).

    Args:
        poses: T_object_element of every element, (E, 4, 4).
        tolerance: penetration tolerated, metres.
        obstacles: ``(normals (P, 3), offsets (P,))`` of the obstacle planes.
        elements: ``(hull, hull_start, sphere, radius, contact, kind, bounds, planes,
            plane_start, element_patches, last_patch)``: hull vertices (H, 3) of element ``e`` at
            ``hull_start[e]:hull_start[e + 1]``; bounding sphere centres (E, 3) and radii (E,);
            contact flags (E,); kind (E,) (0 open, 1 closed convex, 2 closed non-convex); link
            frame boxes (E, 2, 3); convex face planes (F, 4) at ``plane_start[e]:plane_start[e + 1]``;
            patches ``element_patches[e]:element_patches[e + 1]``; the patch of the last vertex (E,).
        patches: ``(samples, offsets, margin, patch_start, patch_size, patch_radius,
            patch_margin, box_lo, box_hi)``: the samples of every patch (S, 3) at
            ``patch_start[p]:patch_start[p] + patch_size[p]``, its centre first, link frame; their
            offsets from the centre (S, 3) and prediction bounds (S,) (0 at the centres); per patch
            its radius, the prediction bound at that radius and the box of its offsets (P, 3).
        surface: ``(points, normals, tree, probes, probes_x, lo, hi, cover, neighbours)``: the
            object's tangent planes and their tree (:attr:`isf.nearest.NearestPoints.tree`); its
            own points (the probes inside elements) sorted by x, and their x; its box; the cover
            (m) and the neighbour count of the estimate.
        voxels: ``(present, table, steps, lo, size)`` of :class:`isf.collision_voxels.SurfaceVoxels`.

    Returns:
        ``(depth, where, clearance, act, summary, candidates, candidate_owner, candidate_guess,
        estimates)``: depth (E,) and its obstacle (E,) (plane index, P for the object, -1 for
        none) so far; the obstacle planes' clearance, m; the active elements (A,) and their
        :func:`_summaries` (A, 6); the clearance candidates (C, 3), their elements (C,) and the
        object points nearest their patch centres (C,) (none when the clearance is 0 already);
        the number of exact estimates made.
    """
    stack_node, stack_bound, stack_offset = search_scratch()
    search = (np.empty(surface[8]), np.empty(surface[8], np.int64), stack_node, stack_bound, stack_offset)
    depth, where, clearance, deep, apart, clearance_bound, estimates = _planes_and_spheres(
        poses, obstacles, elements, surface, voxels, search)
    act = np.flatnonzero(deep | apart)
    none = (np.empty((0, 3)), np.empty(0, np.int64), np.empty(0, np.int64))
    if len(act) == 0:
        return depth, where, clearance, act, np.zeros((0, 6)), none[0], none[1], none[2], estimates
    patch, pk, need, outside_patch, sd, plane, nearest, foot, count = _patch_centres(
        poses, act, deep, apart, clearance_bound, elements, patches, surface, voxels, search)
    estimates += count
    row, rp, pred, lo, hi, seg, last_row = _rows(
        poses, tolerance, act, deep, apart, patch, pk, need, outside_patch, sd, plane, nearest, elements,
        patches, surface)
    count, deepest = _refine(poses, tolerance, depth.max(), clearance, act, deep, outside_patch, row, pred,
                             lo, hi, seg, elements, patches, surface, search)
    estimates += count
    summary = _summaries(poses, act, deep, outside_patch, pred, lo, hi, seg, last_row, deepest, elements,
                         surface)
    if clearance == 0.0:
        return depth, where, clearance, act, summary, none[0], none[1], none[2], estimates
    candidates, owner, guess = _clearance_candidates(poses, act, apart, row, rp, pk, foot, patches[0],
                                                     surface[0])
    return depth, where, clearance, act, summary, candidates, owner, guess, estimates
