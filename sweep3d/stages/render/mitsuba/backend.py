"""The Mitsuba 3 engine's :class:`~..backend.Backend`: its part of the render key, and what it
cannot express (refused at ``plan``, before anything renders).

Mitsuba renders the same plain-Python scene (:class:`~..state.SceneState`) as Cycles; its key
names the engine, Mitsuba's version and the variant in place of Blender's version, which then
changes none of its pixels. Nothing here imports Mitsuba: the version comes from the package's
metadata.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sweep3d.assets import MITSUBA_FORMATS, check_materials
from sweep3d.core import SpecError
from sweep3d.stages.render.backend import Backend, can_be, refuse_when

if TYPE_CHECKING:
    from sweep3d.spec import LoadedSpec
    from sweep3d.stages.render.mitsuba.scene import MitsubaScene

#: Mitsuba's variant when set (benchmarks); None: :func:`mitsuba_variant` picks it by what this machine has.
MITSUBA_VARIANT: str | None = None
#: LLVM libraries Dr.Jit's ``llvm_ad_rgb`` runs on (Debian's ``libllvm19``); Debian 12's default
#: LLVM 14 cannot compile Mitsuba 3.9's kernels, so it is never picked up by a search of Dr.Jit's own.
LLVM_LIBRARIES = ("/usr/lib/x86_64-linux-gnu/libLLVM-19.so", "/usr/lib/llvm-19/lib/libLLVM.so",
                  "/usr/lib/aarch64-linux-gnu/libLLVM-19.so")
#: Bump when sweep3d's own translation of a scene into Mitsuba's (the OBJ/MTL reader, materials,
#: lights, the world, the filter) changes its pixels: part of every Mitsuba render key.
#: 2: poses on the vertices, suns by to_world (kept.py); 3: the denoiser's aux pass apart; 4: the object
#: posed by an instance, renders replayed by Dr.Jit (frozen.py), the aux pass through a box filter, a tent
#: pixel filter (scene.py); 5: under a JIT variant the tent filter sampled by importance, a pixel the mean
#: of its samples, the denoiser's albedo and normals along the camera's rays (frozen.py)
MITSUBA_TRANSLATION = 5
#: Mesh files the Mitsuba engine reads (its own OBJ/MTL reader: ``mitsuba/objfile.py``).
MITSUBA_MESHES = (".obj",)

#: ``[render]`` settings only Cycles reads, and what each is to Cycles: the Mitsuba engine ignores
#: them, so a spec setting one to anything but its default is refused (the default changes nothing).
CYCLES_ONLY = {
    "dither": "Blender's noise before the 8-bit quantisation; the mitsuba engine does not dither",
    "world_sampling": "how Cycles importance-samples the world; Mitsuba's envmap samples its own way",
    "world_map_resolution": "the side of Cycles' world importance map; Mitsuba's envmap has none",
    "adaptive_threshold": "Cycles' adaptive sampling; the mitsuba engine takes every sample",
}


def mitsuba_version() -> str:
    """The installed Mitsuba's version (a :class:`SpecError`-free empty string when it is missing:
    :meth:`MitsubaBackend.check_setup` refuses such a spec first)."""
    try:
        return metadata.version("mitsuba")
    except metadata.PackageNotFoundError:
        return ""


def llvm_library() -> str | None:
    """The LLVM library ``llvm_ad_rgb`` runs on: the user's ``DRJIT_LIBLLVM_PATH``, else the first
    of :data:`LLVM_LIBRARIES` present (None: none, and Mitsuba renders with ``scalar_rgb``)."""
    chosen = os.environ.get("DRJIT_LIBLLVM_PATH")
    if chosen:
        return chosen
    return next((p for p in LLVM_LIBRARIES if Path(p).exists()), None)


def mitsuba_variant() -> str:
    """Mitsuba's variant here: ``llvm_ad_rgb`` where LLVM is present (its kernels, kept per worker
    scene, render a quickstart job in about 0.4 of ``scalar_rgb``'s time: benchmarks/RESULTS.md,
    "Mitsuba at half Cycles' cost"), ``scalar_rgb`` otherwise. Part of every Mitsuba render key."""
    if MITSUBA_VARIANT:
        return MITSUBA_VARIANT
    return "llvm_ad_rgb" if llvm_library() else "scalar_rgb"


def _material(spaces: Mapping[str, Any]) -> str | None:
    if can_be(spaces, "skin", lambda v: v != "original"):
        return "skins are Blender shader nodes and cannot be rendered"
    if can_be(spaces, "emission", lambda v: v not in (None, 0, 0.0)):
        return "emission cannot be rendered"
    return None


#: What the Mitsuba engine cannot render of the built-in controls, once per control type.
SUPPORT = {
    "sky": refuse_when("enabled", bool, "Blender's procedural sky cannot be rendered"),
    "pin_to_ground": refuse_when("enabled", bool, "the ground is a Cycles shadow catcher, which cannot be rendered"),
    "material": _material,
}


class MitsubaBackend(Backend):
    """Mitsuba 3 on the CPU: its own OBJ/MTL reader, no UV pass, no scene edits, Cycles' settings ignored."""

    name = "mitsuba"
    title = "Mitsuba"
    passes = frozenset({"mask", "depth"})
    ignored_settings = CYCLES_ONLY
    support = SUPPORT
    #: Per 224² render, on Cycles' basis (its figures in cycles/backend.py), by the variant this
    #: machine renders with. llvm_ad_rgb (the scene kept per worker, the object posed by an
    #: instance, the render replayed by Dr.Jit, a pixel the mean of its own samples with the
    #: denoiser's albedo and normals along the same rays, OpenImageDenoise "fast"): 0.49× Cycles'
    #: CPU a render at the quickstart's 4 samples (0.50× its time; load about 2), its samples about
    #: 0.13× Cycles' cost each (benchmarks/engine_cost.py and mitsuba_denoise.py; RESULTS.md, "Mitsuba
    #: at a fraction of Cycles' cost" and "2026-11-29: the film's splatting left out"). scalar_rgb:
    #: the issue-45 measurement, 2.2× Cycles' CPU a sample and 0.17 s more a render ("The Mitsuba
    #: engine's cost in plan's estimate"), made before those changes: an upper bound.
    seconds_224 = (0.0045, 0.042) if llvm_library() else (0.075, 0.19)

    def scene(self, settings, scratch, log=None, gpu=None) -> MitsubaScene:
        """A ``MitsubaScene`` (imported only now: Cycles' workers never load Mitsuba)."""
        from sweep3d.stages.render.mitsuba.scene import MitsubaScene

        return MitsubaScene(settings, scratch, log, gpu)

    def key(self) -> dict[str, Any]:
        return {"name": self.name, "version": mitsuba_version(), "variant": mitsuba_variant(),
                "translation": MITSUBA_TRANSLATION}

    def variant(self) -> str:
        return mitsuba_variant()

    def note(self) -> str | None:
        """The line a run says once when it renders with the slower ``scalar_rgb``."""
        if mitsuba_variant() != "scalar_rgb":
            return None
        return ("the mitsuba engine renders with its scalar_rgb variant (no LLVM 19 library found): llvm_ad_rgb "
                "renders about 2.5x faster; install it with apt-get install libllvm19 (or set DRJIT_LIBLLVM_PATH)")

    def check_setup(self, spec: LoadedSpec) -> None:
        """Mitsuba must be installed, and renders on the CPU."""
        path = str(spec.path)
        if not mitsuba_version():
            raise SpecError(path, "render.engine", "engine \"mitsuba\" needs the mitsuba package: pip install mitsuba")
        if spec.render.device in ("cuda", "optix"):
            raise SpecError(path, "render.device", f"device {spec.render.device!r} is Cycles'; the mitsuba engine "
                                                   "renders on the CPU (use \"auto\" or \"cpu\")")

    def check_objects(self, spec: LoadedSpec) -> None:
        """Only OBJ meshes (with their MTL), textures Mitsuba reads, and no smoothing by angle."""
        path = str(spec.path)
        for i, obj in enumerate(spec.objects):
            mesh = spec.meshes[obj.name]
            suffix = Path(str(mesh).partition("#")[2] or str(mesh)).suffix.lower()
            if suffix not in MITSUBA_MESHES:
                raise SpecError(path, f"objects[{i}].mesh", f"the mitsuba engine reads only .obj meshes (with their "
                                                            f"MTL), not {suffix or 'this file'}")
            for where, fmt in check_materials(mesh).base_textures:
                if fmt not in MITSUBA_FORMATS:
                    raise SpecError(path, f"objects[{i}].mesh",
                                    f"{where}: a {fmt} texture, which the mitsuba engine cannot read (it reads "
                                    f"{', '.join(sorted(MITSUBA_FORMATS))}); save it as PNG and name that in the MTL")
            if obj.auto_smooth is not None:
                raise SpecError(path, f"objects[{i}].auto_smooth", "the mitsuba engine cannot smooth by angle; "
                                                                   "remove auto_smooth")
