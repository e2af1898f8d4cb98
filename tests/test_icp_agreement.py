"""With the fingers locked and the normal term off, ISF is point-to-plane ICP: compare with Open3D."""

import numpy as np
import pytest
from _builders import bumpy_object, bumpy_patch, parallel_gripper, random_rotation
from _open3d import import_open3d

from isf.config import FitConfig
from isf.fitting.fit import fit
from isf.se3 import make_transform, rotation_angle

o3d = import_open3d()  # the test extra installs it; a missing reference must fail, not skip

Q0 = 0.02


def _gripper_on_bumps(rng):
    """Pads that lie exactly on the bumpy surface when T = I and q = Q0."""
    pads = []
    for x_range, shift in (((-0.03, -0.008), +Q0), ((0.008, 0.03), -Q0)):
        x = rng.uniform(*x_range, 300)
        y = rng.uniform(-0.012, 0.012, 300)
        points, normals = bumpy_patch(x, y, up=False)
        # the left link sits at -Q0 y at q = Q0, the right at +Q0 y
        pads.append((points + [0.0, shift, 0.0], normals))
    return parallel_gripper(pads[0], pads[1], q_initial=Q0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_locked_fingers_without_normal_term_match_open3d_icp(seed):
    rng = np.random.default_rng(seed)
    gripper = _gripper_on_bumps(rng)
    obj = bumpy_object(n=30000, half=0.045, seed=seed)
    T0 = make_transform(random_rotation(rng, np.radians(3)), rng.uniform(-0.003, 0.003, 3))

    config = FitConfig(levels=1, max_iterations=300, tolerance=1e-9, normal_weight=0.0,
                       lock_fingers=True, reject_duplicates=False, outlier_factor=1e9,
                       max_ipfo_iterations=1)
    ours = fit(gripper, obj, T0, config=config).T_object_gripper

    source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(gripper.contact_points(gripper.q_initial)[0]))
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(obj.points))
    target.normals = o3d.utility.Vector3dVector(obj.normals)
    reference = o3d.pipelines.registration.registration_icp(
        source, target, 1.0, T0,
        o3d.pipelines.registration.TransformationEstimationPointToPlane(),
        o3d.pipelines.registration.ICPConvergenceCriteria(1e-14, 1e-14, 300),
    ).transformation

    assert np.linalg.norm(ours[:3, 3] - reference[:3, 3]) < 1e-4
    assert rotation_angle(ours[:3, :3].T @ reference[:3, :3]) < 1e-3
    # and both found the pose the pads were cut from
    assert np.linalg.norm(ours[:3, 3]) < 1e-4
    assert rotation_angle(ours[:3, :3]) < 1e-3
