"""Random tabletop scenes seen by simulated depth cameras, with their ground truth.

A benchmark module (imported by ``bench/bench_scenes.py`` and the tests); nothing here ships with
isf.

Frames
------
``scene``
    Metres, z up; the table top is the plane z = ``Scene.table_height`` (0). Objects rest on it
    inside an area of ``AREA`` (x, y) centred on the origin.
``object``
    Each object's mesh file frame (YCB: metres, as the files are; the ten YCB meshes span
    2-21 cm, the real objects' sizes). ``SceneObject.T_scene_object`` places it.
``camera``
    The usual depth-image convention: x right, y down, z forward along the optical axis. Pixel
    (u, v) = (column, row) looks along ``((u - cx) / fx, (v - cy) / fy, 1)``; its depth is the
    camera-frame z of the surface it sees (not the ray length). ``Camera.T_scene_camera``
    places it.

Scenes (:func:`random_scene`)
-----------------------------
3-8 distinct objects drawn from a :func:`catalogue` (the YCB meshes, vertices merged so each is
watertight) in stable resting poses (``trimesh.poses.compute_stable_poses``, computed once per
object; poses of probability below ``MIN_POSE_PROBABILITY`` dropped), a random yaw and a random
position in the area, rejected while the object's full mesh meets one already placed (coal's
mesh-mesh distance). With probability ``touch_probability`` the object is then slid towards its
nearest neighbour by conservative advancement (each step moves it by the current distance less
a margin, so it never enters another mesh) until the gap is below ``TOUCH_GAP`` (0.5 mm): the
scene then holds touching neighbours. Everything is drawn from ``numpy.random.default_rng(seed)``.

Rendering (:func:`render`)
--------------------------
Open3D's ``RaycastingScene`` casts one ray per pixel at the posed object meshes and the table
(a 2 x 2 m square, larger than any view's footprint within ``max_range``). The ideal depth then
passes through :class:`SensorModel`, whose parameters model an active stereo camera of the
Intel RealSense D400 kind at 320 x 240:

* axial noise, Gaussian, ``sigma = sigma_reference * (z / reference_depth)**2 +
  angle_noise / sqrt(z) * theta**2 / (pi/2 - theta)**2`` (metres, z in metres, theta the
  incidence angle): the quadratic growth with distance is the stereo error law
  ``RMS = z**2 * subpixel / (f * baseline)`` of Intel's depth-tuning white paper (D435: 50 mm
  baseline, subpixel 0.08 gives 1-1.5 mm at 0.6 m; ``sigma_reference`` 1 mm at 0.6 m), and the
  angle term is the one Nguyen, Izadi and Lovell fitted to Kinect data ("Modeling Kinect Sensor
  Noise for Improved 3D Reconstruction and Tracking", 3DIMPVT 2012: 0.1 mm / sqrt(z) times
  theta^2 / (pi/2 - theta)^2), negligible below 45 deg and dominant near grazing;
* missing pixels at grazing incidence: the probability of losing a pixel ramps linearly from 0
  at ``grazing_start_deg`` (70 deg) to 1 at ``grazing_limit_deg`` (80 deg), where Nguyen et al.
  saw the noise diverge and stereo matching fails on foreshortened texture;
* stereo occlusion shadows: a surface point is only measured if it is also visible from the
  second imager, ``baseline`` (50 mm) along the camera's +x (a second ray cast), which leaves the
  band of missing pixels beside every foreground edge that real stereo depth maps show;
* depth edges: pixels with a 4-neighbour whose depth differs by more than
  ``edge_jump * depth`` (2 %) are edge pixels; ``edge_dropout`` (30 %) of them are lost and
  ``flying_fraction`` (30 %) become flying pixels with a depth drawn uniformly between the
  foreground and the background depth (the mixed pixels of Sabov and Krueger, "Identification
  and correction of flying pixels in range camera data", SCCG 2008);
* range: depths outside [``min_range``, ``max_range``] = [0.2, 2.0] m are lost; depths are
  rounded to ``quantization`` (1 mm, a 16-bit PNG in millimetres).

Lateral (in-image) noise is not modelled. Missing pixels have depth 0. :meth:`SensorModel.ideal`
turns every effect off (for tests).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

import numpy as np
import trimesh

import _common

#: Size of the area objects are placed in, (x, y), metres, centred on the scene origin.
AREA = (0.5, 0.4)
#: Gap below which two objects count as touching after sliding, metres.
TOUCH_GAP = 5e-4
#: Stable poses less likely than this (trimesh's quasi-static estimate) are not used.
MIN_POSE_PROBABILITY = 0.02
#: YCB objects no gripper of the benchmark can grasp in any resting pose: the can is 102 mm
#: across (the Franka hand opens 80 mm, flat-parallel 86 mm); the cracker box lies on its
#: 164 x 213 mm face with high probability, leaving only its 72 mm height to close on.
TOO_LARGE = ("ycb:MasterChefCan", "ycb:CrackerBox")
#: Half size of the square table mesh, metres.
TABLE_HALF_SIZE = 1.0


# --------------------------------------------------------------------------- objects


@dataclass(frozen=True, eq=False)
class CatalogueObject:
    """One object a scene can hold.

    Attributes:
        name: the benchmark name, e.g. ``"ycb:Banana"``.
        mesh: the watertight mesh in its file frame, metres.
        rest_poses: transforms from the file frame to resting poses, (K, 4, 4): the mesh rests on
            z = 0 with its bounding box centred on x = y = 0.
        probabilities: how likely each resting pose is, (K,), summing to 1.
    """

    name: str
    mesh: trimesh.Trimesh
    rest_poses: np.ndarray
    probabilities: np.ndarray


@functools.cache
def catalogue_object(name: str) -> CatalogueObject:
    """Load benchmark object ``name`` (``isf.assets.benchmark_object``) with its resting poses.

    Raises:
        isf.assets.YCBNotFoundError: a ``ycb:`` name and no YCB folder.
    """
    from isf import assets

    asset = assets.benchmark_object(name)
    mesh = trimesh.load(asset.path, force="mesh")
    mesh.apply_scale(asset.scale)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)  # OBJ seams split the surface
    mesh.fix_normals()
    transforms, probabilities = trimesh.poses.compute_stable_poses(mesh)
    keep = probabilities >= MIN_POSE_PROBABILITY
    if not keep.any():
        keep = probabilities == probabilities.max()
    poses = []
    for T in transforms[keep]:
        bounds = trimesh.transform_points(mesh.vertices, T)
        low, high = bounds.min(axis=0), bounds.max(axis=0)
        centred = np.eye(4)
        centred[:3, 3] = [-(low[0] + high[0]) / 2, -(low[1] + high[1]) / 2, -low[2]]
        poses.append(centred @ T)
    p = probabilities[keep]
    return CatalogueObject(name, mesh, np.array(poses), p / p.sum())


def catalogue(names: list[str] | None = None) -> list[CatalogueObject]:
    """The scene objects: ``names``, or every YCB object except :data:`TOO_LARGE`.

    Raises:
        isf.assets.YCBNotFoundError: no YCB folder (set ``ISF_YCB_DIR``).
    """
    from isf import assets

    if names is None:
        names = [n for n in assets.benchmark_objects("ycb") if n not in TOO_LARGE]
    return [catalogue_object(n) for n in names]


@dataclass(frozen=True, eq=False)
class SceneObject:
    """One object of a scene's ground truth.

    Attributes:
        name: unique in its scene, e.g. ``"ycb:Banana"``.
        mesh: watertight mesh in the object frame, metres.
        T_scene_object: pose of the object frame in the scene frame, (4, 4).
    """

    name: str
    mesh: trimesh.Trimesh
    T_scene_object: np.ndarray

    @functools.cached_property
    def posed_mesh(self) -> trimesh.Trimesh:
        """The mesh in the scene frame."""
        return self.mesh.copy().apply_transform(self.T_scene_object)


@dataclass(frozen=True, eq=False)
class Scene:
    """Ground truth of a tabletop scene.

    Attributes:
        objects: the objects on the table.
        table_height: z of the table top in the scene frame, metres.
        seed: the seed it was drawn with (None when built by hand).
    """

    objects: tuple[SceneObject, ...]
    table_height: float = 0.0
    seed: int | None = None

    @property
    def names(self) -> list[str]:
        return [o.name for o in self.objects]

    def without(self, name: str) -> Scene:
        """This scene with object ``name`` taken away (the rest untouched)."""
        if name not in self.names:
            raise KeyError(f"no object {name!r} in the scene; it holds {self.names}")
        return replace(self, objects=tuple(o for o in self.objects if o.name != name))


# --------------------------------------------------------------------------- placement


def _bvh(mesh: trimesh.Trimesh):
    import coal

    model = coal.BVHModelOBBRSS()
    model.beginModel(len(mesh.faces), len(mesh.vertices))
    model.addVertices(np.ascontiguousarray(mesh.vertices, dtype=np.float64))
    model.addTriangles(np.ascontiguousarray(mesh.faces, dtype=np.int64))
    model.endModel()
    return model


@functools.cache
def _object_bvh(name: str):
    return _bvh(catalogue_object(name).mesh)


def _transform(T: np.ndarray):
    import coal

    return coal.Transform3s(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


def mesh_gap(a: SceneObject, b: SceneObject) -> float:
    """Distance between the full meshes of two catalogue objects (coal), metres; 0 when they
    intersect."""
    import coal

    result = coal.DistanceResult()
    return float(coal.distance(_object_bvh(a.name), _transform(a.T_scene_object),
                               _object_bvh(b.name), _transform(b.T_scene_object),
                               coal.DistanceRequest(), result))


def _gap_to(obj: SceneObject, placed: list[SceneObject]) -> tuple[float, int]:
    """Smallest mesh distance from ``obj`` to any of ``placed`` and the index of that one."""
    gaps = [mesh_gap(obj, other) for other in placed]
    k = int(np.argmin(gaps))
    return gaps[k], k


def _moved(obj: SceneObject, shift: np.ndarray) -> SceneObject:
    T = obj.T_scene_object.copy()
    T[:3, 3] += shift
    return SceneObject(obj.name, obj.mesh, T)


def _slide_to_touch(obj: SceneObject, placed: list[SceneObject], iterations: int = 60
                    ) -> SceneObject:
    """Slide ``obj`` (horizontally) towards the nearest of ``placed`` by conservative
    advancement until the gap to any placed object is below :data:`TOUCH_GAP`; an object that
    would pass its neighbour stays at the closest position found."""
    gap, k = _gap_to(obj, placed)
    direction = placed[k].T_scene_object[:3, 3] - obj.T_scene_object[:3, 3]
    direction[2] = 0.0
    if np.linalg.norm(direction) < 1e-9:
        return obj
    direction /= np.linalg.norm(direction)
    best = (gap, obj)
    for _ in range(iterations):
        if gap < TOUCH_GAP:
            break
        candidate = _moved(obj, direction * (gap - TOUCH_GAP / 2))
        gap_new, _ = _gap_to(candidate, placed)
        if gap_new <= 0.0 or gap_new >= gap:  # passed by, or numerical contact: keep the best
            break
        obj, gap = candidate, gap_new
        best = min(best, (gap, obj), key=lambda pair: pair[0])
    return best[1]


def random_scene(objects: list[CatalogueObject], n_objects: int, seed: int,
                 touch_probability: float = 0.5, attempts: int = 200) -> Scene:
    """A random tabletop scene of ``n_objects`` distinct objects drawn from ``objects``.

    Args:
        objects: the catalogue (:func:`catalogue`).
        n_objects: 1 .. len(objects).
        seed: seeds every random choice.
        touch_probability: chance that an object is slid until it touches a neighbour.
        attempts: random positions tried per object before the object is left out.

    Returns:
        the scene (fewer objects than asked only if ``attempts`` positions all collided).
    """
    if not 1 <= n_objects <= len(objects):
        raise ValueError(f"n_objects must be in 1..{len(objects)}, got {n_objects}")
    rng = np.random.default_rng(seed)
    chosen = rng.choice(len(objects), size=n_objects, replace=False)
    half = np.array(AREA) / 2
    placed: list[SceneObject] = []
    for index in chosen:
        item = objects[index]
        rest = item.rest_poses[rng.choice(len(item.rest_poses), p=item.probabilities)]
        for _ in range(attempts):
            yaw = rng.uniform(0.0, 2 * np.pi)
            T = np.eye(4)
            T[:3, :3] = trimesh.transformations.rotation_matrix(yaw, [0, 0, 1])[:3, :3]
            T[:2, 3] = rng.uniform(-half, half)
            obj = SceneObject(item.name, item.mesh, T @ rest)
            if placed and _gap_to(obj, placed)[0] <= 0.0:
                continue
            if placed and rng.uniform() < touch_probability:
                obj = _slide_to_touch(obj, placed)
            placed.append(obj)
            break
    return Scene(tuple(placed), 0.0, seed)


# --------------------------------------------------------------------------- cameras


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics: focal lengths and principal point in pixels, image size."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @classmethod
    def from_fov(cls, width: int = 320, height: int = 240, fov_x_deg: float = 60.0) -> Intrinsics:
        """Square pixels, principal point at the image centre, horizontal field of view in
        degrees."""
        f = (width / 2) / np.tan(np.radians(fov_x_deg) / 2)
        return cls(f, f, (width - 1) / 2, (height - 1) / 2, width, height)

    def pixel_rays(self) -> np.ndarray:
        """Ray of every pixel in the camera frame, ``((u - cx) / fx, (v - cy) / fy, 1)``,
        (height, width, 3)."""
        u, v = np.meshgrid(np.arange(self.width), np.arange(self.height))
        return np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy,
                         np.ones(u.shape)], axis=-1)


@dataclass(frozen=True)
class Camera:
    """A depth camera: intrinsics and ``T_scene_camera`` (4, 4), camera frame x right, y down,
    z forward."""

    intrinsics: Intrinsics
    T_scene_camera: np.ndarray


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``T_scene_camera`` of a camera at ``eye`` looking at ``target`` (scene frame, metres),
    image rows running downwards (the camera's y has a negative scene-z component)."""
    z = np.asarray(target, float) - np.asarray(eye, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = eye
    return T


def random_cameras(rng: np.random.Generator, count: int = 1, distance=(0.5, 0.9),
                   elevation_deg=(30.0, 70.0), intrinsics: Intrinsics | None = None,
                   target: np.ndarray | None = None) -> list[Camera]:
    """``count`` cameras looking at ``target`` (default the scene origin) from a random distance
    and elevation above the table, a random azimuth; a second camera sits 90-180 deg of azimuth
    from the first."""
    intrinsics = intrinsics or Intrinsics.from_fov()
    target = np.zeros(3) if target is None else np.asarray(target, float)
    azimuth = rng.uniform(0, 2 * np.pi)
    cameras = []
    for _ in range(count):
        r, el = rng.uniform(*distance), np.radians(rng.uniform(*elevation_deg))
        eye = target + r * np.array([np.cos(el) * np.cos(azimuth), np.cos(el) * np.sin(azimuth),
                                     np.sin(el)])
        cameras.append(Camera(intrinsics, look_at(eye, target)))
        azimuth += rng.uniform(np.pi / 2, np.pi)
    return cameras


# --------------------------------------------------------------------------- sensor


@dataclass(frozen=True)
class SensorModel:
    """Depth-sensor effects (see the module docstring for the model and its sources).

    Attributes:
        sigma_reference: axial noise std at ``reference_depth``, metres.
        reference_depth: metres.
        angle_noise: coefficient of the incidence-angle noise term, m * sqrt(m).
        grazing_start_deg, grazing_limit_deg: incidence angles between which the chance of a
            missing pixel ramps from 0 to 1, degrees.
        baseline: offset of the second imager along the camera's +x, metres (0: no shadows).
        edge_jump: relative depth step that makes a depth edge.
        edge_dropout: share of edge pixels lost.
        flying_fraction: share of edge pixels given a depth between foreground and background.
        min_range, max_range: measurable depths, metres.
        quantization: depth resolution, metres (0: none).
    """

    sigma_reference: float = 0.001
    reference_depth: float = 0.6
    angle_noise: float = 1e-4
    grazing_start_deg: float = 70.0
    grazing_limit_deg: float = 80.0
    baseline: float = 0.05
    edge_jump: float = 0.02
    edge_dropout: float = 0.3
    flying_fraction: float = 0.3
    min_range: float = 0.2
    max_range: float = 2.0
    quantization: float = 0.001

    @classmethod
    def ideal(cls) -> SensorModel:
        """No noise, no missing or flying pixels, no quantization."""
        return cls(sigma_reference=0.0, angle_noise=0.0, grazing_start_deg=90.0,
                   grazing_limit_deg=90.0, baseline=0.0, edge_dropout=0.0, flying_fraction=0.0,
                   quantization=0.0)

    def sigma(self, depth: np.ndarray, incidence: np.ndarray) -> np.ndarray:
        """Axial noise std (metres) at ``depth`` (metres) and ``incidence`` (radians)."""
        theta = np.minimum(incidence, np.radians(89.0))
        return (self.sigma_reference * (depth / self.reference_depth) ** 2
                + self.angle_noise / np.sqrt(np.maximum(depth, 1e-3))
                * theta**2 / (np.pi / 2 - theta) ** 2)


#: Label of a pixel that sees the table / nothing (``DepthView.labels``).
TABLE, NOTHING = -1, -2


@dataclass(frozen=True, eq=False)
class DepthView:
    """One rendered depth image and what it shows.

    Attributes:
        depth: (H, W) camera-frame z of the measured surface, metres; 0 = missing.
        camera: intrinsics and ``T_scene_camera``.
        labels: (H, W) what the ideal ray of each pixel hits: the index into
            ``scene.objects``, :data:`TABLE` or :data:`NOTHING`.
        scene: the ground truth rendered.
    """

    depth: np.ndarray
    camera: Camera
    labels: np.ndarray
    scene: Scene = field(repr=False)

    @property
    def n_points(self) -> int:
        """Pixels with a measured depth."""
        return int(np.count_nonzero(self.depth))

    def points(self) -> np.ndarray:
        """The measured pixels back-projected into the scene frame, (N, 3), metres."""
        valid = self.depth > 0
        local = self.camera.intrinsics.pixel_rays()[valid] * self.depth[valid, None]
        T = self.camera.T_scene_camera
        return local @ T[:3, :3].T + T[:3, 3]

    def sees(self, point: np.ndarray, tolerance: float = 0.005) -> bool:
        """Whether a pixel of the 3 x 3 block around the projection of ``point`` (scene frame,
        metres) measured a depth within ``tolerance`` of the point's depth: the camera saw that
        surface point (it was neither hidden nor missing)."""
        T = self.camera.T_scene_camera
        local = T[:3, :3].T @ (np.asarray(point, float) - T[:3, 3])
        intr = self.camera.intrinsics
        if local[2] <= 0:
            return False
        u = int(round(intr.fx * local[0] / local[2] + intr.cx))
        v = int(round(intr.fy * local[1] / local[2] + intr.cy))
        block = self.depth[max(v - 1, 0):max(v + 2, 0), max(u - 1, 0):max(u + 2, 0)]
        return bool(np.any((block > 0) & (np.abs(block - local[2]) <= tolerance)))

    def object_pixels(self) -> dict[str, int]:
        """Measured pixels per object name (by the ideal labels)."""
        measured = self.labels[self.depth > 0]
        return {o.name: int(np.count_nonzero(measured == k))
                for k, o in enumerate(self.scene.objects)}


def _raycasting_scene(scene: Scene):
    """An Open3D ``RaycastingScene`` of the posed objects (geometry ids 0..n-1) and the table
    (id n)."""
    o3d = _common.import_open3d()
    rc = o3d.t.geometry.RaycastingScene()
    meshes = [o.posed_mesh for o in scene.objects]
    h, z = TABLE_HALF_SIZE, scene.table_height
    meshes.append(trimesh.Trimesh([[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z]],
                                  [[0, 1, 2], [0, 2, 3]], process=False))
    for mesh in meshes:
        rc.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
                         o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)))
    return rc


def _cast(rc, origins: np.ndarray, directions: np.ndarray) -> dict[str, np.ndarray]:
    o3d = _common.import_open3d()
    rays = np.concatenate([origins, directions], axis=1).astype(np.float32)
    return {k: v.numpy() for k, v in rc.cast_rays(o3d.core.Tensor(rays)).items()}


def _edges(z: np.ndarray, jump: float) -> tuple[np.ndarray, np.ndarray]:
    """Depth-edge pixels of ``z`` (H, W; inf = no surface) and, for each, the farthest and the
    nearest depth among it and its 4-neighbours, stacked (2, H, W)."""
    padded = np.pad(z, 1, mode="edge")
    neighbours = np.stack([padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2],
                           padded[1:-1, 2:], z])
    near, far = neighbours.min(axis=0), neighbours.max(axis=0)
    with np.errstate(invalid="ignore"):
        edge = np.isfinite(z) & (far - near > jump * near)
    return edge, np.stack([near, far])


def render(scene: Scene, camera: Camera, sensor: SensorModel | None = None,
           rng: np.random.Generator | int = 0) -> DepthView:
    """Render ``scene`` from ``camera`` through ``sensor`` (default :class:`SensorModel`).

    Args:
        scene: the ground truth.
        camera: intrinsics and pose.
        sensor: the sensor effects; :meth:`SensorModel.ideal` for the exact depth.
        rng: a generator or a seed for the sensor's random effects.
    """
    sensor = sensor or SensorModel()
    rng = np.random.default_rng(rng)
    intr, T = camera.intrinsics, camera.T_scene_camera
    rays_camera = intr.pixel_rays().reshape(-1, 3)
    directions = rays_camera @ T[:3, :3].T
    origins = np.broadcast_to(T[:3, 3], directions.shape)
    rc = _raycasting_scene(scene)
    hit = _cast(rc, origins, directions)
    z = hit["t_hit"].astype(float)  # direction has camera z = 1, so t is the depth
    ids = hit["geometry_ids"].astype(np.int64)
    found = np.isfinite(z)
    labels = np.where(~found, NOTHING, np.where(ids == len(scene.objects), TABLE, ids))

    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    cos_incidence = np.abs(np.einsum("ij,ij->i", hit["primitive_normals"], unit))
    incidence = np.arccos(np.clip(cos_incidence, 0.0, 1.0))
    lost = np.zeros(len(z), dtype=bool)
    if sensor.baseline > 0 and found.any():  # the second imager must see the point too
        points = origins[found] + directions[found] * z[found, None]
        second = T[:3, 3] + sensor.baseline * T[:3, 0]
        towards = second - points
        length = np.linalg.norm(towards, axis=1)
        start = points + 1e-4 * towards / length[:, None]
        back = _cast(rc, start, towards / length[:, None])["t_hit"]
        lost[np.flatnonzero(found)[back < length - 2e-4]] = True
    ramp = sensor.grazing_limit_deg - sensor.grazing_start_deg
    if ramp > 0:
        p_grazing = np.clip((np.degrees(incidence) - sensor.grazing_start_deg) / ramp, 0, 1)
        lost |= rng.uniform(size=len(z)) < p_grazing

    sigma = np.where(found, sensor.sigma(np.where(found, z, 1.0), incidence), 0.0)
    depth = np.where(found, z + rng.normal(size=len(z)) * sigma, 0.0)

    edge, (near, far) = _edges(z.reshape(intr.height, intr.width), sensor.edge_jump)
    edge, near, far = edge.ravel(), near.ravel(), far.ravel()
    draw = rng.uniform(size=len(z))
    flying = edge & np.isfinite(far) & (draw < sensor.flying_fraction)
    with np.errstate(invalid="ignore"):
        mixed = near + rng.uniform(size=len(z)) * (np.where(np.isfinite(far), far, near) - near)
    depth = np.where(flying, mixed + rng.normal(size=len(z)) * sensor.sigma(mixed, 0.0), depth)
    lost |= edge & (draw >= sensor.flying_fraction) & (
        draw < sensor.flying_fraction + sensor.edge_dropout)
    lost |= ~found | (depth < sensor.min_range) | (depth > sensor.max_range)
    depth[lost] = 0.0
    if sensor.quantization > 0:
        depth = np.round(depth / sensor.quantization) * sensor.quantization
    return DepthView(depth.reshape(intr.height, intr.width), camera,
                     labels.reshape(intr.height, intr.width), scene)
