"""Mitsuba's copy of a job: what a render worker keeps and renders when the engine is Mitsuba.

:class:`MitsubaScene` is a :class:`~sweep3d.stages.render.backend.RenderScene`, as a ``BlenderScene``
is (``prepare``, ``pose_scene``, ``render_png``, ``truth_pass``, ``parts``, ``load_seconds``,
``rebuild_if_stale``), so the stage, the pool, the blobs and the rows are the
same for both engines. An object is read once per (mesh, look) into triangle meshes per material
(PLY files in the worker's scratch folder); each job then describes the whole scene, and
:mod:`.kept` updates the worker's loaded scene in place when only values changed (a fresh
``mitsuba.load_dict`` otherwise) and renders it.

Pixels follow Cycles' output: linear radiance, OpenImageDenoise with albedo and normals when
the settings (or the ``denoiser`` control) ask, Blender's "Standard" view transform (the sRGB
curve, clipped), 8 bits, and a plain background composited behind the object's coverage.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sweep3d.core import TRUTH_PASSES, UserError, encode_png
from sweep3d.spec import unknown_name
from sweep3d.stages.render.lights import WHITE, SunLight
from sweep3d.stages.render.mitsuba import translate
from sweep3d.stages.render.mitsuba.backend import llvm_library, mitsuba_variant
from sweep3d.stages.render.mitsuba.frozen import FrozenRender
from sweep3d.stages.render.mitsuba.hdri import load_bitmap
from sweep3d.stages.render.mitsuba.kept import KeptScene
from sweep3d.stages.render.mitsuba.objfile import MtlMaterial, ObjMesh, read_obj
from sweep3d.stages.render.state import SceneState
from sweep3d.stages.render.worker_protocol import EnvironmentRef, Look, RenderSettings

#: The pixel filter's radius in pixels under ``scalar_rgb`` (a JIT variant renders each pixel as the
#: mean of its own samples, a box of the same 0.29–0.31 px standard deviation, its film's splatting
#: 20 ms CPU a render: frozen.py): a tent as wide as Cycles' 1.5 px Blackman-Harris. Its
#: standard deviation (0.31 px) is the Gaussian's that it replaced (0.3 px; 54–60 dB apart at 256
#: samples), whose 1.2 px reach (4 standard deviations) spread each sample over more pixels of
#: Mitsuba's film: 61 against 52 ms CPU of a 4-sample 224² render's path tracing (toaster in studio;
#: benchmarks/RESULTS.md, "Mitsuba at a fraction of Cycles' cost").
FILTER_RADIUS = 0.75
#: OpenImageDenoise's quality for Mitsuba's renders, chosen by measurement against Mitsuba's own
#: 512-sample renders of the quickstart's scenes (benchmarks/RESULTS.md, "Mitsuba at half Cycles'
#: cost"): at 4 samples "fast" is 36.7 dB from them against 38.0 dB for "high" (Cycles' own), in
#: half the time; the denoiser is most of a render's cost.
DENOISE_QUALITY = "fast"
#: Names of the object's instance and of the group of its pieces (``object_0000``, …) in a scene
#: description: every shape of the object is named from "object".
OBJECT, OBJECT_PARTS = "object", "object_parts"
#: The name of the camera's twin that sees the denoiser's albedo and normals under ``scalar_rgb``
#: (:func:`aux_sensor`; a JIT variant reads them along the camera's own rays: frozen.py).
AUX_SENSOR = "aux_sensor"
#: Objects (mesh, look) a worker keeps read, least recently used first out (as Cycles' workers keep 16).
MAX_KEPT_OBJECTS = 16


def load_mitsuba(variant: str | None = None) -> Any:
    """``mitsuba`` with ``variant`` (default: ``backend.mitsuba_variant()``) set, an llvm variant on
    ``backend.llvm_library()`` (Dr.Jit's own search could find Debian's LLVM 14, which fails),
    errors only in the log.

    Raises:
        UserError: mitsuba is not installed, or the variant cannot run here.
    """
    variant = variant or mitsuba_variant()
    library = llvm_library()
    if variant.startswith("llvm") and library:
        os.environ["DRJIT_LIBLLVM_PATH"] = library
    try:
        import mitsuba as mi
    except ImportError:
        raise UserError("engine \"mitsuba\" needs the mitsuba package: pip install mitsuba") from None
    try:
        mi.set_variant(variant)
    except (ImportError, AttributeError, RuntimeError) as exc:
        raise UserError(f"Mitsuba's variant {variant!r} cannot run here: {exc}") from None
    mi.set_log_level(mi.LogLevel.Error)
    return mi


@dataclass
class LoadedMesh:
    """One (mesh, look) read for Mitsuba: a PLY file and a material per piece, and its normalisation."""

    files: list[tuple[str, str]]  # (PLY path, material name)
    materials: dict[str, dict[str, Any]]  # material name → Principled values (the look applied)
    textures: dict[str, str]  # material name → its base colour texture (absent when overridden)
    centre: np.ndarray
    radius: float
    points: np.ndarray  # a subsample of the vertices (Blender axes), for the silhouette's bounds
    where: str


class MitsubaScene:
    """A render worker's Mitsuba scene (the ``BlenderScene`` interface; module docstring).

    Args:
        log, gpu: as ``BlenderScene``'s; unused (Mitsuba prints nothing and renders on the CPU).
    """

    def __init__(self, settings: RenderSettings, scratch: Path, log: Any = None, gpu: int | None = None) -> None:
        self.mi = load_mitsuba(settings.variant or None)
        self.settings = settings
        self.scratch = scratch
        self.folder = scratch / f"mitsuba-{os.getpid()}"
        self.folder.mkdir(parents=True, exist_ok=True)
        if settings.threads:
            import drjit as dr

            dr.set_thread_count(settings.threads)
        self.loading = False
        self.load_seconds = 0.0
        self.parts: dict[str, Any] | None = None  # no UV pass (refused at plan)
        self.objects: dict[tuple[str, Look | None], LoadedMesh] = {}
        self.current: LoadedMesh | None = None
        self.environment = EnvironmentRef()
        self.state = SceneState()
        self.textures: dict[str, Any] = {}  # texture path → loaded bitmap, shared by jobs
        self.hdris: dict[str, Any] = {}  # HDRI path → its bitmap as Blender reads it (hdri.py)
        self.loaded: Any = None  # the latest job's loaded Mitsuba scene
        self.aux_integrator: Any = None  # _aux()
        self.kept = KeptScene(self.mi, self.converted)  # loaded once per structure, updated per job (kept.py)
        self.frozen = FrozenRender(self.mi)  # renders replayed without tracing them again (frozen.py)
        # the object posed by an instance (a new pose rebuilds only Embree's top level, where moving
        # the vertices rebuilt the mesh's BVH: 25 ms a job for the quickstart's toaster), but not under
        # scalar_rgb: Mitsuba 3.9's scalar path tracer crashes on an instance with hide_emitters
        self.instanced = not self.mi.variant().startswith("scalar")
        self.serial = 0  # names each read object's PLY files
        self.stale = False
        truth = tuple(p for p in settings.passes if p in TRUTH_PASSES)
        from sweep3d.stages.render.mitsuba.passes import MitsubaTruth

        self.truth_pass = MitsubaTruth(self, truth) if truth else None

    # -- the BlenderScene interface ------------------------------------------------------------
    def prepare(self, mesh_path: str, environment: EnvironmentRef, look: Look | None = None) -> None:
        """Make ``mesh_path`` (as ``look`` shows it) and ``environment`` the job's, reading the mesh
        the first time (that job's :attr:`load_seconds`)."""
        started = time.perf_counter()
        ref = (mesh_path, look)
        self.loading = self.current is None or environment != self.environment or self.objects.get(ref) is not self.current
        if ref not in self.objects:
            self.objects[ref] = self._load(mesh_path, look)
        self.objects[ref] = self.objects.pop(ref)  # most recently used last
        while len(self.objects) > MAX_KEPT_OBJECTS:  # the least recently used goes, with its files
            old = self.objects.pop(next(iter(self.objects)))
            for ply, _ in old.files:
                Path(ply).unlink(missing_ok=True)
        self.current, self.environment = self.objects[ref], environment
        self.load_seconds = time.perf_counter() - started if self.loading else 0.0

    def pose_scene(self, state: SceneState) -> None:
        """Keep the job's state: the scene is described whole when it renders."""
        self.state = state

    def render_png(self) -> bytes:
        """Render the job as the blob's PNG (RGB, 8 bits), and its truth passes when asked."""
        png = encode_png(self.render())
        if self.truth_pass is not None:
            self.truth_pass.read(self)
        return png

    def rebuild_if_stale(self) -> None:
        """Nothing to rebuild: no control edits a Mitsuba scene (``edit`` is refused at plan)."""

    # -- rendering -----------------------------------------------------------------------------
    def render(self) -> np.ndarray:
        """The job's image: float32 (H, W, 3), sRGB values in [0, 1], as ``BlenderScene.render``."""
        s, state = self.settings, self.state
        denoise = s.denoise if state.denoise is None else state.denoise
        background = self.background()
        path = {"type": "path", "max_depth": s.max_bounces + 1, "hide_emitters": background is not None}
        traced = self.frozen.replayed is not None  # a JIT variant: sweep3d's own loop (frozen.py)
        sensor = translate.camera(state, s.resolution, s.crop, FILTER_RADIUS)
        if traced:  # each pixel the mean of its own samples, no splatting (frozen.py)
            sensor["film"]["rfilter"] = {"type": "box"}
        scene = self.describe(path, sensor)
        twin = denoise and not traced
        if twin:  # scalar_rgb: the denoiser's albedo and normals seen by a twin of the camera (aux_sensor)
            scene[AUX_SENSOR] = aux_sensor(scene["sensor"])
        self.loaded = self.kept.scene_for(scene)  # the truth passes look at the same scene
        # the denoiser's albedo and normals from a first-hit pass over the same samples (under a JIT
        # variant along the camera's own rays, in the same kernel: frozen.py): the path tracer nested
        # in an ``aov`` integrator took twice as long for the same pixels
        camera = sensor_index(self.loaded, "sensor")
        image, aux = self.frozen(self.loaded, s.samples, s.seed, self._aux() if denoise else None,
                                 (camera, sensor_index(self.loaded, AUX_SENSOR) if twin else camera),
                                 hash(self.kept.key))
        rgb, alpha = np.maximum(image[..., :3], 0.0), np.clip(image[..., 3:4], 0.0, 1.0)
        if aux is not None:
            import pyoidn

            albedo = np.clip(aux[..., -6:-3], 0.0, 1.0)
            normal = np.clip(aux[..., -3:], -1.0, 1.0)
            rgb = np.maximum(pyoidn.denoise(np.ascontiguousarray(rgb), np.ascontiguousarray(albedo),
                                            np.ascontiguousarray(normal), hdr=True,
                                            clean_aux=s.denoise_prefilter != "accurate",  # as Cycles
                                            quality=DENOISE_QUALITY), 0.0)
        if background is None:
            return srgb(rgb)
        straight = srgb(rgb / np.maximum(alpha, 1e-6))  # Blender's transparent film: straight alpha
        return straight * alpha + np.asarray(background, dtype=np.float32) * (1.0 - alpha)

    def _aux(self) -> Any:
        """The first-hit integrator of the denoiser's albedo and normals, loaded once per worker
        (a new one per job would compile its kernels again)."""
        if self.aux_integrator is None:
            self.aux_integrator = self.mi.load_dict({"type": "aov", "aovs": "albedo:albedo,normal:sh_normal"})
        return self.aux_integrator

    def background(self) -> tuple[float, float, float] | None:
        """The plain colour composited behind the object (None: the world is seen)."""
        env, state = self.environment, self.state
        return state.background or (tuple(env.color) if env.color else None)

    def describe(self, integrator: dict[str, Any], sensor: dict[str, Any], scenery: bool = True,
                 lit: bool = True) -> dict[str, Any]:
        """The job's scene for Mitsuba's ``load_dict`` (``scenery``: with the occluder; ``lit``:
        with the world and the lights, which a pass that only finds surfaces does without)."""
        state, env, loaded = self.state, self.environment, self.current
        assert loaded is not None, "prepare() first"
        sensor = {"sampler": {"type": "multijitter"}, **sensor}  # stratified: less noise than independent at 4 spp
        scene: dict[str, Any] = {"type": "scene", "integrator": integrator, "sensor": sensor}
        if lit:
            scene["world"] = self._world(env, state)
            scene.update(translate.lights(state.lights + self._key_light(env, state), state))
        edits = self._edited(loaded, state)
        matrix = translate.object_matrix(state, loaded.centre, loaded.radius)
        pieces = {f"object_{i:04d}": {"type": "ply", "filename": ply,
                                      "bsdf": self._bsdf(loaded, material, edits.get(material, {}))}
                  for i, (ply, material) in enumerate(loaded.files)}
        if self.instanced:  # the pieces untransformed in a group, posed by one instance's to_world
            scene[OBJECT_PARTS] = {"type": "shapegroup", **pieces}
            scene[OBJECT] = {"type": "instance", "shapegroup": {"type": "ref", "id": OBJECT_PARTS}, "to_world": matrix}
        else:  # each piece posed (kept.py moves their vertices)
            scene.update({name: {**piece, "to_world": matrix} for name, piece in pieces.items()})
        plate = translate.occluder(state) if scenery else None
        if plate is not None:
            scene["scenery_occluder"] = plate
        return scene

    def load(self, scene: dict[str, Any]) -> Any:
        """A description (matrices as numpy arrays) loaded afresh, its values set as the kept scene's are."""
        return KeptScene(self.mi, self.converted).scene_for(scene)

    def converted(self, value: Any) -> Any:
        """A description with its numpy 4×4 matrices as Mitsuba transforms."""
        if isinstance(value, dict):
            return {k: self.converted(v) for k, v in value.items()}
        if isinstance(value, np.ndarray) and value.shape == (4, 4):
            return self.mi.ScalarTransform4f(value.tolist())
        return value

    def _world(self, env: EnvironmentRef, state: SceneState) -> dict[str, Any]:
        """An HDRI as Blender's world shows it, or a plain colour's uniform white light (dimmed
        to the key light's fill), both times the environment's and the job's strength."""
        strength = env.strength * state.world_strength
        if env.hdri:
            bitmap = self.hdris.get(env.hdri)
            if bitmap is None:
                bitmap = self.hdris[env.hdri] = load_bitmap(self.mi, env.hdri)
            return {"type": "envmap", "bitmap": bitmap, "scale": strength,
                    "to_world": translate.envmap_to_world(state.world_rotation)}
        if env.key_light is not None:
            strength *= env.key_light.fill
        return {"type": "constant", "radiance": {"type": "rgb", "value": [strength] * 3}}

    @staticmethod
    def _key_light(env: EnvironmentRef, state: SceneState) -> list[SunLight]:
        """A plain colour's key light, as ``BlenderScene._key_light`` makes it."""
        key = env.key_light
        if key is None:
            return []
        strength = key.strength * env.strength * state.world_strength
        return [SunLight(WHITE, strength, key.angle, key.azimuth, key.elevation, key.relative_to)]

    def _edited(self, loaded: LoadedMesh, state: SceneState) -> dict[str, dict[str, Any]]:
        """The job's material edits (the ``material`` control) per material name.

        Raises:
            UserError: an edit's target names no material of the object (Cycles' wording)."""
        out: dict[str, dict[str, Any]] = {}
        names = sorted(loaded.materials)
        for target, pairs in state.material_edits:
            if target and target not in loaded.materials:
                raise UserError(f"the material control's target {target!r} is no material of {loaded.where} "
                                f"(its materials: {', '.join(names) or 'none'})")
            for name in names:
                if target in ("", name):
                    out.setdefault(name, {}).update(pairs)
        return out

    def _bsdf(self, loaded: LoadedMesh, material: str, edits: dict[str, Any]) -> dict[str, Any]:
        values = {**loaded.materials[material], **edits}
        texture_path = loaded.textures.get(material) if "base_color" not in edits else None
        texture = None
        if texture_path is not None:
            texture = self.textures.get(texture_path)
            if texture is None:
                texture = self.textures[texture_path] = self.mi.load_dict({"type": "bitmap", "filename": texture_path})
        return translate.principled(values, texture)

    # -- loading -------------------------------------------------------------------------------
    def _load(self, mesh_path: str, look: Look | None) -> LoadedMesh:
        """Read a mesh file as its look shows it into PLY files (one per object and material).

        Raises:
            UserError: a part or material the file lacks, or nothing to render.
        """
        path = Path(mesh_path)
        where = path.name
        if path.suffix.lower() != ".obj":
            raise UserError(f"the mitsuba engine reads only .obj meshes, not {where!r}")
        mesh = read_obj(path)
        pieces = mesh.pieces
        if look is not None and look.parts:
            objects = mesh.objects()
            for part in look.parts:
                if part not in objects:
                    raise UserError(unknown_name("object", part, objects, where) + "; give one of its objects")
            pieces = [p for p in pieces if p.object_name in look.parts]
        if not pieces:
            raise UserError(f"{mesh_path!r} contains no faces to render")
        points = np.concatenate([p.positions for p in pieces])
        if not np.isfinite(points).all():
            raise UserError(f"{mesh_path!r} has no finite vertices to render")
        centre = (points.min(axis=0) + points.max(axis=0)) / 2.0
        radius = float(np.sqrt(((points - centre) ** 2).sum(axis=1).max()))
        if not radius > 0:
            raise UserError(f"{mesh_path!r} has zero size (all vertices coincide)")
        materials, textures = self._materials(mesh, {p.material for p in pieces}, look, where)
        self.serial += 1
        stem = f"{self.serial:05d}"
        files = []
        for i, piece in enumerate(pieces):
            ply = self.folder / f"{stem}-{i:04d}.ply"
            write_ply(ply, piece.positions, piece.normals, piece.uvs)
            files.append((str(ply), piece.material))
        step = max(1, len(points) // 20000)
        return LoadedMesh(files, materials, textures, centre, radius, points[::step], where)

    @staticmethod
    def _materials(mesh: ObjMesh, used: set[str], look: Look | None,
                   where: str) -> tuple[dict[str, dict[str, Any]], dict[str, str]]:
        """The used materials' Principled values with the look's overrides (all, then per name),
        and the textures an override of the base colour does not replace."""
        values: dict[str, dict[str, Any]] = {}
        textures: dict[str, str] = {}
        named = dict(look.materials) if look is not None else {}
        for name in named:
            if name not in used:
                raise UserError(unknown_name("material", name, sorted(used - {""}), f"the rendered parts of {where}")
                                + "; give one of its materials")
        for name in sorted(used):
            own = mesh.materials.get(name, MtlMaterial(name))
            v: dict[str, Any] = {"base_color": own.base_color, "roughness": own.roughness, "metallic": own.metallic,
                                 "specular": own.specular, "ior": own.ior, "opacity": own.opacity,
                                 "transmission": own.transmission, "coat": own.coat}
            if look is not None:
                v.update(dict(look.material))
                v.update(dict(named.get(name, ())))
            values[name] = v
            if own.texture and "base_color" not in dict(look.material if look else ()) | dict(named.get(name, ())):
                textures[name] = own.texture
        return values, textures


def aux_sensor(sensor: dict[str, Any]) -> dict[str, Any]:
    """The camera's twin for the denoiser's albedo and normals: the same view, samples and seed
    through a box filter. Each sample then lands in one pixel, where the Gaussian's overlapping
    footprint cost the first-hit pass 20 ms of its 27 (toaster in studio, 224², 4 samples) for
    0.16 dB against Mitsuba's 512-sample renders (benchmarks/RESULTS.md, "Mitsuba at a fraction of
    Cycles' cost")."""
    return {**sensor, "film": {**sensor["film"], "rfilter": {"type": "box"}}}


def sensor_index(loaded: Any, name: str) -> int:
    """The place of the sensor ``name`` among a loaded scene's (``mitsuba.render``'s ``sensor``)."""
    return next(i for i, sensor in enumerate(loaded.sensors()) if sensor.id() == name)


def srgb(linear: np.ndarray) -> np.ndarray:
    """Blender's "Standard" view transform: the sRGB curve of linear values, clipped to [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055).astype(np.float32)


def write_ply(path: Path, positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray | None) -> None:
    """A binary PLY of unshared triangles (three vertices per face) Mitsuba's ``ply`` reads.

    Texture ``v`` is flipped: OBJ counts it up from the image's bottom, Mitsuba's bitmaps from its top."""
    n = len(positions)
    columns = [positions.astype(np.float32), normals.astype(np.float32)]
    names = ["x", "y", "z", "nx", "ny", "nz"]
    if uvs is not None:
        columns.append(np.stack([uvs[:, 0], 1.0 - uvs[:, 1]], axis=1).astype(np.float32))
        names += ["u", "v"]
    vertices = np.ascontiguousarray(np.concatenate(columns, axis=1), dtype="<f4")
    faces = np.empty(n // 3, dtype=[("count", "u1"), ("index", "<i4", (3,))])
    faces["count"] = 3
    faces["index"] = np.arange(n, dtype=np.int32).reshape(-1, 3)
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {n}",
              *(f"property float {name}" for name in names), f"element face {n // 3}",
              "property list uchar int vertex_indices", "end_header"]
    with open(path, "wb") as out:
        out.write(("\n".join(header) + "\n").encode())
        out.write(vertices.tobytes())
        out.write(faces.tobytes())
