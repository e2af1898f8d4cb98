"""What the collision checks derive from an object's mesh is built once per mesh, and let go."""

import gc

import numpy as np
import trimesh

import isf
from isf.collision.checker import CollisionChecker, object_bvh
from isf.collision.surface_distance import _MESH_MEMOS, closed_mesh
from isf.planning._working_surface import working_surface


def box_object():
    return isf.load_object(trimesh.creation.box(extents=(0.04, 0.03, 0.05)), voxel_size=0.002)


def test_a_mesh_is_processed_once_and_shared_with_its_working_surface():
    obj = box_object()
    thin = working_surface(obj, 3 * obj.spacing)
    assert thin is not obj and thin.mesh_faces is obj.mesh_faces
    assert object_bvh(thin) is object_bvh(obj)
    assert closed_mesh(thin) is closed_mesh(obj) is not None
    # a copy of the arrays is another mesh as far as the memo knows
    copy = isf.ObjectSurface(obj.points, obj.normals, obj.spacing,
                             mesh_vertices=obj.mesh_vertices.copy(), mesh_faces=obj.mesh_faces.copy())
    assert object_bvh(copy) is not object_bvh(obj)


def test_checks_with_a_memoised_mesh_equal_checks_with_a_fresh_one():
    gripper = isf.load_gripper("paper-parallel")
    obj = box_object()
    first = CollisionChecker(gripper, obj)  # builds the memo
    again = CollisionChecker(gripper, obj)  # reuses it
    fresh_obj = isf.ObjectSurface(obj.points, obj.normals, obj.spacing, name=obj.name,
                                  mesh_vertices=obj.mesh_vertices.copy(),
                                  mesh_faces=obj.mesh_faces.copy())
    fresh = CollisionChecker(gripper, fresh_obj)
    rng = np.random.default_rng(0)
    for _ in range(5):
        T = np.eye(4)
        T[:3, 3] = rng.uniform(-0.03, 0.03, 3)
        q = gripper.q_initial
        a, b, c = (k.check(T, q) for k in (first, again, fresh))
        assert a.collision_free == b.collision_free == c.collision_free
        assert a.penetration == b.penetration == c.penetration
        assert a.clearance == b.clearance == c.clearance


def test_the_memo_goes_with_the_mesh():
    obj = box_object()
    object_bvh(obj)
    key = id(obj.mesh_faces)
    assert key in _MESH_MEMOS
    del obj
    gc.collect()
    assert key not in _MESH_MEMOS
