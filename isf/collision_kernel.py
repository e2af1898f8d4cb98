"""The compiled body of a collision check: culling, patches, predictions, refinement, depths.

:func:`check_elements` runs, in one call per check, everything :mod:`isf.collision` describes
up to the exact clearance measurements: the obstacle planes, the culling of elements and
patches (object box, voxels, bounding spheres), the tangent-plane estimate at the patch
centres, the first-order predictions with their trust bounds, the refinement rounds, each
element's depth summaries, the object points inside its convex elements and the clearance
candidates. Its arrays are prepared once per checker (:func:`isf.collision._packed`).

Conventions: ``poses`` (E, 4, 4) place the elements in the object frame; a *row* is one
sample of an opened patch, or the centre of a patch that stays closed, in patch order; an
element's rows are contiguous.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .collision_elements import convex_depth
from .collision_surface import estimate
from .collision_voxels import box_clear, distance_below
from .nearest import search_scratch

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


@njit(cache=True, error_model="numpy")
def _deepest_looking(mask, pred, seg, want):
    """Mark in ``want`` the :data:`DEEPEST_CANDIDATES` rows of ``mask`` with the lowest ``pred``
    (ties: the earlier row) of each element (rows ``seg[k]:seg[k + 1]``)."""
    top = np.empty(DEEPEST_CANDIDATES, np.int64)
    for k in range(len(seg) - 1):
        n = 0
        for r in range(seg[k], seg[k + 1]):
            if not mask[r]:
                continue
            if n == DEEPEST_CANDIDATES and pred[r] >= pred[top[n - 1]]:
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
def _deepest_known(pred, margin, seg, out):
    """Per element: the depth of its deepest exactly evaluated row (``margin == 0``), >= 0."""
    for k in range(len(seg) - 1):
        d = 0.0
        for r in range(seg[k], seg[k + 1]):
            if margin[r] == 0.0 and -pred[r] > d:
                d = -pred[r]
        out[k] = d


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
        surface: ``(points, normals, tree, object_points, lo, hi, cover, neighbours)``: the
            object's tangent planes and their tree (:attr:`isf.nearest.NearestPoints.tree`), its
            own points (the probes inside elements), box, cover (m) and neighbour count.
        voxels: ``(present, table, steps, lo, size)`` of :class:`isf.collision_voxels.SurfaceVoxels`.

    Returns:
        ``(depth, where, clearance, act, summary, candidates, candidate_owner, candidate_guess,
        evaluations)``: depth (E,) and its obstacle (E,) (plane index, P for the object, -1 for
        none) so far; the obstacle planes' clearance, m; the elements whose samples were tested
        (A,); per such element ``[deep, inside_any, outside_any, deepest, last vertex's value,
        convex object depth]`` (A, 6) (see :meth:`isf.collision.CollisionChecker._report`); the clearance
        candidates (C, 3), their elements (C,) and nearest-point guesses (C,); the number of
        exact estimates made.
    """
    normals_p, offsets_p = obstacles
    hull, hull_start, sphere, radius, contact, kind, bounds, planes, plane_start, element_patches, \
        last_patch = elements
    samples, offsets, margin0, patch_start, patch_size, patch_radius, patch_margin, box_lo, box_hi = patches
    points, normals, tree, object_points, olo, ohi, cover, neighbours = surface
    has_voxels, table, steps, vlo, vsize = voxels
    tp, order, t_start, t_stop, t_axis, t_split, t_left, t_right = tree
    stack_node, stack_bound, stack_offset = search_scratch()
    best_d2, best = np.empty(neighbours), np.empty(neighbours, np.int64)
    n_el = len(poses)
    evaluations = 0

    # ---------------------------------------------------------------- planes and culling
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
    for p in range(len(offsets_p)):
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
    near = np.zeros(n_el, np.bool_)
    for e in range(n_el):
        near[e] = (ehi[e, 0] >= olo[0] and ehi[e, 1] >= olo[1] and ehi[e, 2] >= olo[2]
                   and elo[e, 0] <= ohi[0] and elo[e, 1] <= ohi[1] and elo[e, 2] <= ohi[2])
        if near[e] and has_voxels:
            near[e] = not box_clear(table, vlo, vsize, elo[e, 0] - VOXEL_MARGIN, elo[e, 1] - VOXEL_MARGIN,
                                    elo[e, 2] - VOXEL_MARGIN, ehi[e, 0] + VOXEL_MARGIN,
                                    ehi[e, 1] + VOXEL_MARGIN, ehi[e, 2] + VOXEL_MARGIN)
    # bounding spheres: the signed distance of the centre less the radius bounds the element's;
    # the distance to the nearest object point plus the radius bounds its clearance
    lower = np.full(n_el, np.inf)
    clearance_bound = clearance
    for e in range(n_el):
        if not (near[e] or not contact[e]):
            continue
        x, y, z = _transform(poses, e, sphere[e, 0], sphere[e, 1], sphere[e, 2])
        sd, _, nearest, _ = estimate(x, y, z, best_d2, best, points, normals, tp, order, t_start, t_stop,
                                      t_axis, t_split, t_left, t_right, stack_node, stack_bound, stack_offset)
        evaluations += 1
        lower[e] = min(sd, nearest - cover) - radius[e]
        if not contact[e]:
            clearance_bound = min(clearance_bound, nearest + radius[e])
    deep, apart = np.zeros(n_el, np.bool_), np.zeros(n_el, np.bool_)
    n_act = 0
    for e in range(n_el):
        deep[e] = near[e] and lower[e] < CULL_MARGIN
        apart[e] = not contact[e] and lower[e] < clearance_bound
        n_act += deep[e] or apart[e]
    act = np.empty(n_act, np.int64)
    summary = np.zeros((n_act, 6))
    none = (np.empty((0, 3)), np.empty(0, np.int64), np.empty(0, np.int64))
    if n_act == 0:
        return depth, where, clearance, act, summary, none[0], none[1], none[2], evaluations
    k = 0
    for e in range(n_el):
        if deep[e] or apart[e]:
            act[k] = e
            k += 1

    # ---------------------------------------------------------------- patch centres
    n_patch = 0
    for k in range(n_act):
        n_patch += element_patches[act[k] + 1] - element_patches[act[k]]
    patch = np.empty(n_patch, np.int64)
    pk = np.empty(n_patch, np.int64)  # position in act
    centre = np.empty((n_patch, 3))
    gap, need, outside = np.empty(n_patch), np.zeros(n_patch, np.bool_), np.zeros(n_patch, np.bool_)
    i = 0
    for k in range(n_act):
        e = act[k]
        for p in range(element_patches[e], element_patches[e + 1]):
            patch[i], pk[i] = p, k
            s = patch_start[p]
            x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
            centre[i, 0], centre[i, 1], centre[i, 2] = x, y, z
            # a patch farther from the object's box than its radius (or whose ball lies in
            # voxels outside a mesh object) holds no sample inside the object; one farther than
            # its radius plus the clearance bound none nearer to it
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
    sd_c, normal_c, nearest_c, foot_c = np.empty(n_patch), np.empty(n_patch, np.int64), \
        np.empty(n_patch), np.empty(n_patch, np.int64)
    bound = clearance_bound
    for i in range(n_patch):
        if need[i]:
            sd_c[i], normal_c[i], nearest_c[i], foot_c[i] = estimate(
                centre[i, 0], centre[i, 1], centre[i, 2], best_d2, best, points, normals, tp, order,
                t_start, t_stop, t_axis, t_split, t_left, t_right, stack_node, stack_bound, stack_offset)
            evaluations += 1
            if apart[act[pk[i]]]:
                bound = min(bound, nearest_c[i])
    # patches for the clearance: those that may hold samples nearer than an evaluated centre
    for i in range(n_patch):
        if not need[i] and apart[act[pk[i]]] and gap[i] - patch_radius[patch[i]] < bound:
            need[i] = True
            sd_c[i], normal_c[i], nearest_c[i], foot_c[i] = estimate(
                centre[i, 0], centre[i, 1], centre[i, 2], best_d2, best, points, normals, tp, order,
                t_start, t_stop, t_axis, t_split, t_left, t_right, stack_node, stack_bound, stack_offset)
            evaluations += 1
    outside_patch = np.zeros(n_act, np.bool_)  # elements with a patch settled outside
    centre_depth = np.full(n_act, -np.inf)
    any_outside = np.zeros(n_act, np.bool_)  # some evaluated centre has sd >= 0
    for i in range(n_patch):
        if not need[i]:
            outside_patch[pk[i]] |= outside[i]
        else:
            centre_depth[pk[i]] = max(centre_depth[pk[i]], -sd_c[i])
            any_outside[pk[i]] |= sd_c[i] >= 0.0

    # ---------------------------------------------------------------- first-order predictions
    m = np.empty((n_patch, 3))  # the gradient in the link frame: R^T n
    opened = np.zeros(n_patch, np.bool_)
    first_clear, second_clear = -1, -1  # the patches nearest the object of elements wanting clearance
    for i in range(n_patch):
        if not need[i]:
            continue
        k, p = pk[i], patch[i]
        e = act[k]
        n = normal_c[i]
        for j in range(3):
            m[i, j] = poses[e, 0, j] * normals[n, 0] + poses[e, 1, j] * normals[n, 1] + poses[e, 2, j] * normals[n, 2]
        low = sd_c[i] + (min(box_lo[p, 0] * m[i, 0], box_hi[p, 0] * m[i, 0])
                         + min(box_lo[p, 1] * m[i, 1], box_hi[p, 1] * m[i, 1])
                         + min(box_lo[p, 2] * m[i, 2], box_hi[p, 2] * m[i, 2]))
        low_bound = low - patch_margin[p]
        if deep[e]:
            opened[i] = (low_bound < -tolerance  # the verdict
                         or low < -(max(centre_depth[k], 0.0) + DEPTH_RESOLUTION)  # the value
                         or (not contact[e] and not centre_depth[k] > 0.0 and low_bound < 0.0)  # touching?
                         or not (any_outside[k] or outside_patch[k]))  # wholly inside?
        if apart[e]:
            if first_clear < 0 or nearest_c[i] < nearest_c[first_clear]:
                first_clear, second_clear = i, first_clear
            elif second_clear < 0 or nearest_c[i] < nearest_c[second_clear]:
                second_clear = i
    if first_clear >= 0:
        opened[first_clear] = True
    if second_clear >= 0:
        opened[second_clear] = True
    n_rows = 0
    for i in range(n_patch):
        if need[i]:
            n_rows += patch_size[patch[i]] if opened[i] else 1
    row = np.empty(n_rows, np.int64)  # sample of each row
    rp = np.empty(n_rows, np.int64)  # patch (index into the patch arrays) of each row
    pred, margin = np.empty(n_rows), np.empty(n_rows)
    seg = np.zeros(n_act + 1, np.int64)  # rows of act[k]: seg[k]:seg[k + 1]
    last_row = np.empty(n_act, np.int64)
    r = 0
    for i in range(n_patch):
        if not need[i]:
            continue
        k, p = pk[i], patch[i]
        if p == last_patch[act[k]]:
            last_row[k] = r
        size = patch_size[p] if opened[i] else 1
        for s in range(patch_start[p], patch_start[p] + size):
            row[r], rp[r] = s, i
            pred[r] = sd_c[i] + (offsets[s, 0] * m[i, 0] + offsets[s, 1] * m[i, 1] + offsets[s, 2] * m[i, 2])
            margin[r] = margin0[s] if opened[i] else 0.0
            r += 1
        seg[k + 1] = r

    # ---------------------------------------------------------------- refinement rounds
    # Exactly evaluated: the samples that can change a verdict, the deepest value, whether a
    # non-contact element touches, or whether an element lies wholly inside. The first round
    # takes each element's deepest-looking candidates for the verdict, the value and touching;
    # later rounds all remaining verdict candidates of unsettled elements and the value's
    # candidates while the deepest value grows.
    deepest, now = np.empty(n_act), np.empty(n_act)
    _deepest_known(pred, margin, seg, deepest)
    improving = np.ones(n_act, np.bool_)
    flags = np.zeros(n_act, np.bool_)
    plane_depth = 0.0
    for e in range(n_el):
        plane_depth = max(plane_depth, depth[e])
    value, verdict, touch = np.zeros(n_rows, np.bool_), np.zeros(n_rows, np.bool_), np.zeros(n_rows, np.bool_)
    want = np.zeros(n_rows, np.bool_)
    for round_ in range(ROUNDS):
        overall = plane_depth
        for k in range(n_act):
            overall = max(overall, deepest[k])
            # touching: an exactly evaluated row inside; outside: a row certainly outside
            flags[k] = outside_patch[k]
        touching = np.zeros(n_act, np.bool_)
        unknown_any = False
        for k in range(n_act):
            for r in range(seg[k], seg[k + 1]):
                if margin[r] == 0.0 and pred[r] < 0.0:
                    touching[k] = True
                if pred[r] - margin[r] >= 0.0:
                    flags[k] = True
        for k in range(n_act):
            e = act[k]
            for r in range(seg[k], seg[k + 1]):
                unknown = deep[e] and margin[r] != 0.0
                unknown_any |= unknown
                lo = pred[r] - margin[r]
                verdict[r] = unknown and deepest[k] <= tolerance and -lo > tolerance
                value[r] = unknown and -pred[r] > overall + DEPTH_RESOLUTION and improving[k]
                touch[r] = (round_ == 0 and clearance > 0.0 and unknown and not contact[e]
                            and not touching[k] and lo < 0.0)
                want[r] = unknown and not flags[k] and pred[r] + margin[r] >= 0.0  # wholly inside?
                if round_ > 0:
                    want[r] |= verdict[r]
        if not unknown_any:
            break
        _deepest_looking(value, pred, seg, want)
        if round_ == 0:
            _deepest_looking(verdict, pred, seg, want)
            _deepest_looking(touch, pred, seg, want)
        evaluated = False
        for r in range(n_rows):
            if not want[r]:
                continue
            e = act[pk[rp[r]]]
            s = row[r]
            x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
            pred[r] = estimate(x, y, z, best_d2, best, points, normals, tp, order, t_start, t_stop,
                                t_axis, t_split, t_left, t_right, stack_node, stack_bound, stack_offset)[0]
            margin[r] = 0.0
            evaluations += 1
            evaluated = True
        if not evaluated:
            break
        _deepest_known(pred, margin, seg, now)
        for k in range(n_act):
            improving[k] = now[k] > deepest[k]
            deepest[k] = now[k]

    # ---------------------------------------------------------------- depth summaries
    for k in range(n_act):
        e = act[k]
        summary[k, 0] = deep[e]
        if not deep[e]:
            continue
        inside_any, outside_any = False, outside_patch[k]
        for r in range(seg[k], seg[k + 1]):
            inside_any |= (margin[r] == 0.0 and pred[r] < 0.0) or pred[r] + margin[r] < 0.0
            outside_any |= pred[r] - margin[r] >= 0.0
        summary[k, 1], summary[k, 2], summary[k, 3] = inside_any, outside_any, deepest[k]
        summary[k, 4] = pred[last_row[k]]
        if kind[e] == 1:
            summary[k, 5] = convex_depth(object_points, poses[e], bounds[e], planes[plane_start[e]:plane_start[e + 1]])

    # ---------------------------------------------------------------- clearance candidates
    # the samples nearest the nearest samples of the object seen from the centres
    n_free = 0
    for r in range(n_rows):
        n_free += apart[act[pk[rp[r]]]]
    if clearance == 0.0 or n_free == 0:
        return depth, where, clearance, act, summary, none[0], none[1], none[2], evaluations
    far = np.empty(n_free)
    place = np.empty((n_free, 3))
    free_row = np.empty(n_free, np.int64)
    j = 0
    for r in range(n_rows):
        i = rp[r]
        e = act[pk[i]]
        if not apart[e]:
            continue
        s = row[r]
        x, y, z = _transform(poses, e, samples[s, 0], samples[s, 1], samples[s, 2])
        f = foot_c[i]
        place[j, 0], place[j, 1], place[j, 2] = x, y, z
        far[j] = np.sqrt((x - points[f, 0]) ** 2 + (y - points[f, 1]) ** 2 + (z - points[f, 2]) ** 2)
        free_row[j] = r
        j += 1
    take = np.argsort(far, kind="mergesort")[:CLEARANCE_CANDIDATES]
    candidates = np.empty((len(take), 3))
    owner, guess = np.empty(len(take), np.int64), np.empty(len(take), np.int64)
    for j in range(len(take)):
        candidates[j, 0], candidates[j, 1], candidates[j, 2] = place[take[j], 0], place[take[j], 1], place[take[j], 2]
        i = rp[free_row[take[j]]]
        owner[j], guess[j] = act[pk[i]], foot_c[i]
    return depth, where, clearance, act, summary, candidates, owner, guess, evaluations
