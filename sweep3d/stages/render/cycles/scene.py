"""Blender's copy of a :class:`SceneState`: builds a scene once, then re-poses it per job.

A :class:`BlenderScene` keeps every object and every world it has loaded (up to a budget,
least recently used first out): each object (a mesh file as a look shows it: its parts, material
overrides, smoothing; see :mod:`.looks`) sits under its own normalising empty and is hidden
for render and viewport while another is current; each environment has its own bpy World and
``scene.world`` points at the job's. Going back to a scene is a switch, not a re-import. A job
that changes only pose or camera just moves things (persistent render data keeps Cycles' scene
and the world's importance map between renders; Cycles does rebuild the map when
``scene.world`` changes, so the render stage orders jobs world by world).

A job that switches object or world (and a worker's first job) is a *scene load*: its set-up
here and, where a :class:`RenderLog` reads Blender's progress, Cycles' preparation of its render
(BVH, importance map) are timed apart in :attr:`BlenderScene.load_seconds`, so that ``bench``
reports steady-state render time beside the cost of a switch.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sweep3d.core import TRUTH_PASSES, UserError, encode_png
from sweep3d.stages.render.cycles._bpy import import_bpy
from sweep3d.stages.render.cycles._rna import assign
from sweep3d.stages.render.cycles.blender_looks import FileNames, apply_look, rename_imported, select_parts
from sweep3d.stages.render.cycles.lamps import Lamps
from sweep3d.stages.render.cycles.material_edits import MaterialEdits
from sweep3d.stages.render.cycles.props import Props
from sweep3d.stages.render.cycles.skins import SkinMaterials
from sweep3d.stages.render.cycles.truth_pass import TruthPass
from sweep3d.stages.render.cycles.uv_pass import UVPass
from sweep3d.stages.render.cycles.world import WorldNodes
from sweep3d.stages.render.device import use_device
from sweep3d.stages.render.kept import Kept
from sweep3d.stages.render.lights import WHITE, SunLight
from sweep3d.stages.render.render_log import RenderLog
from sweep3d.stages.render.state import SENSOR_WIDTH_MM, SceneState
from sweep3d.stages.render.worker_protocol import EnvironmentRef, Look, RenderSettings

IMPORTERS = {
    ".obj": ("wm.obj_import", {}),
    ".ply": ("wm.ply_import", {}),
    ".stl": ("wm.stl_import", {}),
    ".gltf": ("import_scene.gltf", {}),
    ".glb": ("import_scene.gltf", {}),
}


#: What a worker keeps loaded besides the current scene (see :class:`Kept`). Hidden objects cost
#: only Blender's mesh data (~0.2 kB per face; Cycles drops them); kept worlds cost their HDRI's
#: float RGBA buffer (16 bytes per pixel: 32 Mpx is one 8k map, or eight 2k ones).
MAX_KEPT_OBJECTS = 16
MAX_KEPT_FACES = 2_000_000
MAX_KEPT_WORLDS = 8
MAX_KEPT_HDRI_PIXELS = 32 * 2**20
BLOB_COMPRESSION = 15  # Blender's PNG compression in percent: zlib level 1, as encode_png writes


@dataclass
class LoadedObject:
    """An imported mesh file under its own normalising empty (a child of the pose empty)."""

    normaliser: Any
    objects: list[Any]  # everything the import made
    meshes: list[Any]  # the mesh objects that render (the look's parts)
    radius: float
    own: list[tuple[bool, bool]]  # each object's own (hide_render, hide_viewport), restored when shown
    names: FileNames  # what the file called its objects and materials

    @property
    def faces(self) -> int:
        """Every imported mesh's faces (parts left out are hidden, not removed: they cost memory)."""
        return sum(len(o.data.polygons) for o in self.objects if o.type == "MESH")

    def show(self, visible: bool) -> None:
        """Show the object as imported, or hide it from render and viewport (Cycles drops it)."""
        for obj, (render, viewport) in zip(self.objects, self.own):
            assign(obj, "hide_render", render or not visible)
            assign(obj, "hide_viewport", viewport or not visible)


class BlenderScene:
    """One Blender scene in this process, configured from the spec's render settings.

    Args:
        log: where this process's fd 1 (Blender's progress) goes, read to time Cycles' set-up of
            a render after a scene switch; None (fd 1 elsewhere) times only the loading here.
        gpu: with a GPU device, the number of the one GPU to render on (one worker per GPU);
            None: all of them.

    Raises:
        UserError: ``settings.device`` is a GPU back-end that finds no GPU here.
    """

    def __init__(self, settings: RenderSettings, scratch: Path, log: RenderLog | None = None,
                 gpu: int | None = None) -> None:
        self.bpy = bpy = import_bpy()
        self.settings = settings
        self.scratch = scratch
        self.log = log
        self.gpu = gpu
        self.loading = False  # the current job switched object or world (or is the first)
        self.load_seconds = 0.0  # what that switch cost the current job (0 when it did not switch)
        self.object_ref: str | None = None  # the shown object's mesh ...
        self.look: Look | None = None  # ... and its look
        self.background: tuple[float, float, float] | None = None
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = self.scene = bpy.context.scene
        self._configure(scene, settings)
        use_device(bpy, scene, settings.device, gpu)  # after the factory settings, which reset preferences
        cam_data = bpy.data.cameras.new("sweep3d_camera")
        cam_data.sensor_fit = "HORIZONTAL"
        cam_data.sensor_width = SENSOR_WIDTH_MM
        cam_data.clip_start = 1e-3
        cam_data.clip_end = 1e4
        self.camera = bpy.data.objects.new("sweep3d_camera", cam_data)
        scene.collection.objects.link(self.camera)
        scene.camera = self.camera
        self.pose = bpy.data.objects.new("sweep3d_pose", None)  # controls move this empty
        scene.collection.objects.link(self.pose)
        self.objects: Kept[tuple[str, Look | None], LoadedObject] = Kept(MAX_KEPT_OBJECTS, MAX_KEPT_FACES, lambda o: o.faces)
        self.meshes: list[Any] = []  # the current object's
        self.current: LoadedObject | None = None  # the shown object
        self.worlds: Kept[EnvironmentRef, WorldNodes] = Kept(MAX_KEPT_WORLDS, MAX_KEPT_HDRI_PIXELS, lambda w: w.pixels)
        self.environment = EnvironmentRef()
        self.world = self._world(self.environment)
        scene.world = self.world.world
        self.skins = SkinMaterials(bpy)
        self.material_edits = MaterialEdits(bpy)
        self.props = Props(bpy, scene)
        self.lamps = Lamps(bpy, scene)
        self.frame = scratch / f"frame-{os.getpid()}.png"
        scene.render.filepath = str(self.frame)  # set once: a scene edit's snapshot sees it as the render leaves it
        self.uv_pass = UVPass(bpy, scene, scratch) if "uv" in settings.passes else None
        self.parts: dict[str, Any] | None = None  # what the UV pass saw in the latest render
        truth = tuple(p for p in settings.passes if p in TRUTH_PASSES)
        self.truth_pass = TruthPass(bpy, scene, scratch, truth) if truth else None
        self.stale = False  # a control's edit changed data this scene held: rebuild before the next job

    def reset(self) -> None:
        """Start again from an empty Blender scene (everything loaded is loaded again when next
        needed): for after a control's ``edit`` changed data this scene held (see ``scene_edit``)."""
        self.__init__(self.settings, self.scratch, self.log, self.gpu)

    def rebuild_if_stale(self) -> None:
        """:meth:`reset` when a control's ``edit`` left the scene :attr:`stale`. Called once the
        job's reply is made: a rebuild makes new pass readers, which hold nothing of the render."""
        if self.stale:
            self.reset()

    @staticmethod
    def _configure(scene, s: RenderSettings) -> None:
        scene.render.engine = "CYCLES"
        cycles = scene.cycles
        cycles.samples = s.samples
        cycles.use_adaptive_sampling = bool(s.adaptive_threshold)
        if cycles.use_adaptive_sampling:
            cycles.adaptive_threshold = s.adaptive_threshold
        cycles.seed = s.seed
        cycles.max_bounces = s.max_bounces
        cycles.use_denoising = bool(s.denoise)
        if s.denoise:
            cycles.denoiser = "OPENIMAGEDENOISE"
            cycles.denoising_prefilter = {"fast": "FAST", "accurate": "ACCURATE", "none": "NONE"}[s.denoise_prefilter]
        scene.render.resolution_x = scene.render.resolution_y = s.resolution
        scene.render.resolution_percentage = 100
        _crop_to_centre(scene.render, s.resolution, s.crop or s.resolution)
        scene.render.use_persistent_data = True  # keeps the BVH and the importance map while they stay
        scene.render.threads_mode = "FIXED"
        scene.render.threads = s.threads or os.cpu_count() or 1
        scene.render.dither_intensity = s.dither
        scene.view_settings.view_transform = "Standard"
        scene.view_settings.look = "None"
        scene.render.image_settings.file_format = "PNG"
        scene.render.image_settings.color_mode = "RGBA"
        scene.render.image_settings.color_depth = "8"
        scene.render.image_settings.compression = 0
        for prop in scene.render.bl_rna.properties:  # no dates or timings in the file: blobs are reproducible
            if prop.identifier.startswith("use_stamp_") and prop.identifier != "use_stamp_labels":
                setattr(scene.render, prop.identifier, False)

    # -- loading -------------------------------------------------------------------------------
    def prepare(self, mesh_path: str, environment: EnvironmentRef, look: Look | None = None) -> None:
        """Make ``mesh_path`` (as ``look`` shows it) the shown object and ``environment``'s world the
        scene's (its values are synced by :meth:`pose_scene`); each is loaded only the first time
        it is needed.

        Starts the job's :attr:`load_seconds`: the time spent here when the object or the world
        changed (or nothing was shown yet), else 0."""
        started = time.perf_counter()
        self.loading = self.object_ref is None
        self.environment = environment
        self.world = self._world(environment)
        if self.scene.world != self.world.world:
            self.scene.world = self.world.world
            self.loading = True
        if (mesh_path, look) != (self.object_ref, self.look):
            self._show((mesh_path, look))
            self.object_ref, self.look = mesh_path, look
            self.loading = True
        self.load_seconds = time.perf_counter() - started if self.loading else 0.0

    def _world(self, environment: EnvironmentRef) -> WorldNodes:
        """The environment's own World (one per environment, so a switch rebuilds no node tree)."""
        nodes = self.worlds.get(environment)
        if nodes is None:
            world = self.bpy.data.worlds.new("sweep3d_world")
            world.use_fake_user = True  # out of use while another is current: not an orphan to purge
            world.cycles.sampling_method = self.settings.world_sampling.upper()  # the HDRI's importance map
            world.cycles.sample_map_resolution = self.settings.world_map_resolution
            nodes = WorldNodes(self.bpy, world)
            self.worlds.add(environment, nodes)
        return nodes

    def _evict_worlds(self) -> None:
        """Remove the least recently used worlds beyond the budget, and their HDRIs."""
        evicted = self.worlds.evict()
        for old in evicted:
            self.bpy.data.worlds.remove(old.world)
        if evicted:
            self.bpy.data.orphans_purge(do_recursive=True)

    def _show(self, ref: tuple[str, Look | None]) -> None:
        """Show a (mesh, look)'s object (importing it the first time) and hide every other one."""
        loaded = self.objects.get(ref)
        if loaded is None:
            loaded = self._load_object(*ref)  # a UserError leaves the scene as it was
            self.objects.add(ref, loaded)
        self.material_edits.forget()  # the object going out of sight gets its own materials back
        self.skins.restore()
        for other in self.objects.values():
            other.show(other is loaded)
        self.meshes, self.current = loaded.meshes, loaded
        self.skins.reset(loaded.meshes, loaded.radius)
        evicted = self.objects.evict()
        for old in evicted:
            for obj in old.objects + [old.normaliser]:
                self.bpy.data.objects.remove(obj, do_unlink=True)
        if evicted:
            self.bpy.data.orphans_purge(do_recursive=True)  # their meshes, materials, textures

    def _load_object(self, mesh_path: str, look: Look | None = None) -> LoadedObject:
        """Import ``mesh_path`` under a new normalising empty (unit bounding sphere at the origin
        around what renders: the look's parts), with the look's materials and smoothing."""
        bpy = self.bpy
        before, materials = set(bpy.data.objects), set(bpy.data.materials)
        try:
            self._import(mesh_path)
            imported = [o for o in bpy.data.objects if o not in before]
            names = rename_imported(imported, [m for m in bpy.data.materials if m not in materials])
            where = Path(mesh_path).name
            shown = select_parts(imported, names, look.parts if look else None, where)
            meshes = [o for o in imported if o.type == "MESH" and o in shown]
            if look is not None and look.parts and not meshes:
                raise UserError(f"the parts {', '.join(map(repr, look.parts))} of {where} hold no mesh to render")
            if look is not None:
                apply_look(bpy, meshes, names, look, where)
            centre, radius = self._check(mesh_path, meshes)
        except UserError:
            for obj in [o for o in bpy.data.objects if o not in before]:
                bpy.data.objects.remove(obj, do_unlink=True)
            bpy.data.orphans_purge(do_recursive=True)
            raise
        normaliser = bpy.data.objects.new("sweep3d_normaliser", None)
        self.scene.collection.objects.link(normaliser)
        normaliser.parent = self.pose
        normaliser.scale = (1.0 / radius,) * 3
        normaliser.location = tuple(-centre / radius)
        for obj in imported:
            if obj.parent is None:
                world = obj.matrix_world.copy()
                obj.parent = normaliser
                obj.matrix_parent_inverse.identity()
                obj.matrix_basis = world
        if self.truth_pass is not None:
            for obj in meshes:
                obj.pass_index = 1  # the mask: the object's pixels, not the ground or the occluder
        if self.uv_pass is not None:
            bpy.context.view_layer.update()
            to_pose = self.pose.matrix_world.inverted()
            self.uv_pass.prepare(meshes, lambda obj: to_pose @ obj.matrix_world)
        own = [(o.hide_render, o.hide_viewport) if o in shown else (True, True) for o in imported]
        return LoadedObject(normaliser, imported, meshes, radius, own, names)

    def _import(self, mesh_path: str) -> None:
        op_name, kwargs = IMPORTERS[Path(mesh_path).suffix.lower()]
        module, _, name = op_name.partition(".")
        try:
            getattr(getattr(self.bpy.ops, module), name)(filepath=str(mesh_path), **kwargs)
        except RuntimeError as exc:
            raise UserError(f"Blender cannot import {mesh_path!r}: {exc}") from None

    def _check(self, mesh_path: str, meshes: list[Any]) -> tuple[np.ndarray, float]:
        """The imported meshes' bounding-sphere centre and radius; a UserError if they cannot render."""
        if not meshes:
            raise UserError(f"{mesh_path!r} contains no mesh objects")
        points = self._world_vertices(meshes)
        if len(points) == 0 or not np.all(np.isfinite(points)):
            raise UserError(f"{mesh_path!r} has no finite vertices to render")
        centre = (points.min(axis=0) + points.max(axis=0)) / 2.0
        radius = float(np.sqrt(((points - centre) ** 2).sum(axis=1).max()))
        if not radius > 0:
            raise UserError(f"{mesh_path!r} has zero size (all vertices coincide)")
        faces = sum(len(o.data.polygons) for o in meshes)
        if faces == 0:
            raise UserError(f"{mesh_path!r} has no faces to render (are its face indices valid?)")
        if self._surface_area(meshes) <= 1e-12 * radius**2:
            raise UserError(f"{mesh_path!r} has zero area (its faces are degenerate: all points on a line)")
        return centre, radius

    @staticmethod
    def _surface_area(meshes) -> float:
        total = 0.0
        for obj in meshes:
            areas = np.empty(len(obj.data.polygons), dtype=np.float64)
            obj.data.polygons.foreach_get("area", areas)
            total += float(areas.sum() * abs(np.linalg.det(np.array(obj.matrix_world)[:3, :3])) ** (2 / 3))
        return total

    @staticmethod
    def _world_vertices(meshes) -> np.ndarray:
        chunks = []
        for obj in meshes:
            n = len(obj.data.vertices)
            if n == 0:
                continue
            local = np.empty(n * 3, dtype=np.float64)
            obj.data.vertices.foreach_get("co", local)
            local = local.reshape(n, 3)
            m = np.array(obj.matrix_world)
            chunks.append(local @ m[:3, :3].T + m[:3, 3])
        return np.concatenate(chunks) if chunks else np.empty((0, 3))

    # -- per job -------------------------------------------------------------------------------
    def pose_scene(self, state: SceneState) -> None:
        """Make the scene match ``state``: pose, camera, world, lights, material, props.

        Only what differs from the previous job is touched; no file is reloaded.
        """
        self.pose.rotation_mode = "XYZ"
        self.pose.rotation_euler = (math.radians(state.pitch), math.radians(state.roll), math.radians(state.yaw))
        self.pose.scale = (state.scale,) * 3
        self.pose.location = tuple(state.object_location())
        position, right, up, forward = state.camera_basis()
        assign(self.camera.data, "lens", state.focal_length)
        from mathutils import Matrix  # noqa: PLC0415  (ships with bpy)

        rotation = Matrix([list(right), list(up), list(-forward)]).transposed()
        self.camera.matrix_world = Matrix.Translation(position) @ rotation.to_4x4()
        distance = state.camera_distance()
        assign(self.camera.data, "clip_start", max(distance * 1e-4, 1e-6))
        assign(self.camera.data, "clip_end", distance + 1e3 * max(state.scale, 1.0))
        dof = self.camera.data.dof
        assign(dof, "use_dof", state.fstop > 0)
        if dof.use_dof:
            assign(dof, "aperture_fstop", state.fstop)
            assign(dof, "focus_distance", float(np.linalg.norm(state.object_location() - position)))
        denoise = self.settings.denoise if state.denoise is None else state.denoise
        assign(self.scene.cycles, "use_denoising", denoise)
        env = self.environment
        started = time.perf_counter()
        self.world.sync(env, state)  # a new world builds its nodes and loads its HDRI here
        self._evict_worlds()  # now that the job's HDRI is loaded, and its size known
        if self.loading:
            self.load_seconds += time.perf_counter() - started
        self.background = state.background or (tuple(env.color) if env.color and state.sky is None else None)
        assign(self.scene.render, "film_transparent", self.background is not None)
        # Nothing to composite: Blender's own RGB file is the blob (see render_png); else RGBA to composite
        image = self.scene.render.image_settings
        assign(image, "color_mode", "RGBA" if self.background is not None else "RGB")
        assign(image, "compression", 0 if self.background is not None else BLOB_COMPRESSION)
        if self.skins.changes(state.skin, state.skin_scale, state.skin_image):
            self.material_edits.restore()  # the skin swaps the slots' materials: edits go on top again
        self.skins.sync(state.skin, state.skin_scale, state.skin_image)
        self.material_edits.sync(self.meshes, self.current.names, state.material_edits, Path(self.object_ref).name)
        self.lamps.sync(state.lights + self._key_light(env, state), state)
        self.props.sync_occluder(state)
        lowest = None
        if state.pin_to_ground:
            self.bpy.context.view_layer.update()
            lowest = float(self._world_vertices(self.meshes)[:, 2].min())
        self.props.sync_ground(state, lowest)

    @staticmethod
    def _key_light(env: EnvironmentRef, state: SceneState) -> list[SunLight]:
        """A plain colour's key light: a white sun (riding with the camera unless it is world-relative),
        scaled like the world's light (the world keeps ``fill`` of it, see world.py); none under a
        procedural sky."""
        key = env.key_light
        if key is None or state.sky is not None:
            return []
        strength = key.strength * env.strength * state.world_strength
        return [SunLight(WHITE, strength, key.angle, key.azimuth, key.elevation, key.relative_to)]

    def render(self) -> np.ndarray:
        """Render the current scene.

        After a scene switch, adds Cycles' set-up of this render (before its first sample: the
        BVH, the world's importance map) to :attr:`load_seconds`, when a :class:`RenderLog` has it.

        Returns:
            float32 array of shape (H, W, 3) with sRGB values in [0, 1], composited onto the
            plain background colour when the environment has one.
        """
        from PIL import Image  # noqa: PLC0415

        self._render_frame()
        with Image.open(self.frame) as img:
            rgba = np.asarray(img.convert("RGBA"), dtype=np.float32) / 255.0
        rgb, alpha = rgba[..., :3], rgba[..., 3:]
        if self.background is not None:
            rgb = rgb * alpha + np.asarray(self.background, dtype=np.float32) * (1.0 - alpha)
        return rgb

    def render_png(self) -> bytes:
        """Render the current scene as the blob's PNG (RGB, 8 bits): the file Blender wrote when
        nothing is composited behind the render, so it is neither decoded nor encoded again (the
        pixels :meth:`render` gives, quantised); else :meth:`render`'s image encoded."""
        if self.background is not None:
            return encode_png(self.render())
        self._render_frame()
        return self.frame.read_bytes()

    def _render_frame(self) -> None:
        """Render into :attr:`frame` and read the passes; times a scene switch's set-up (see :meth:`render`)."""
        if self.log is not None:
            self.log.clear()
        self.bpy.ops.render.render(write_still=True)
        if self.loading and self.log is not None:
            self.load_seconds += self.log.setup_seconds() or 0.0
        if self.uv_pass is not None:
            self.parts = self.uv_pass.read()
        if self.truth_pass is not None:
            self.truth_pass.read(self)  # may render again, index only, for the visible fraction


def _crop_to_centre(render, size: int, crop: int) -> None:
    """Render only the centre ``crop`` pixels of the ``size`` frame, and output just those.

    A render border keeps the camera, the pixel grid and each pixel's sample pattern of the
    full frame, so the result is the full render's centre crop (the denoiser sees no margin);
    it costs what a ``crop``-sized render of the same view costs. Blender truncates
    ``border * size`` to whole pixels: a quarter pixel inside keeps float error from shifting it.
    """
    render.use_border = render.use_crop_to_border = crop < size
    if crop < size:
        left = (size - crop) // 2  # where Preprocess's centre crop starts, from the top and left
        bottom = size - crop - left  # Blender counts y from the bottom
        render.border_min_x, render.border_max_x = (left + 0.25) / size, (left + crop + 0.25) / size
        render.border_min_y, render.border_max_y = (bottom + 0.25) / size, (bottom + crop + 0.25) / size
