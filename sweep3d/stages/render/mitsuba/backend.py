"""Which renderer makes a spec's images (``[render] engine``), what it adds to the render key, and
what a second renderer cannot express (refused at ``plan``, before anything renders).

Cycles is the default and adds nothing to the key, so its keys are those from before the choice
existed. Mitsuba 3 (``sweep3d.stages.render.mitsuba``) renders the same plain-Python scene
(:class:`~.state.SceneState`); its key names the engine, Mitsuba's version and the variant in
place of Blender's version, which then changes none of its pixels. Nothing here imports
Mitsuba: the version comes from the package's metadata.
"""

from __future__ import annotations

import os
from importlib import metadata
from pathlib import Path
from typing import Any

from sweep3d.assets import MITSUBA_FORMATS, check_materials
from sweep3d.core import SpecError
from sweep3d.spec import LoadedSpec

ENGINES = ("cycles", "mitsuba")
#: Mitsuba's variant when set (benchmarks); None: :func:`mitsuba_variant` picks it by what this machine has.
MITSUBA_VARIANT: str | None = None
#: LLVM libraries Dr.Jit's ``llvm_ad_rgb`` runs on (Debian's ``libllvm19``); Debian 12's default
#: LLVM 14 cannot compile Mitsuba 3.9's kernels, so it is never picked up by a search of Dr.Jit's own.
LLVM_LIBRARIES = ("/usr/lib/x86_64-linux-gnu/libLLVM-19.so", "/usr/lib/llvm-19/lib/libLLVM.so",
                  "/usr/lib/aarch64-linux-gnu/libLLVM-19.so")
#: Bump when sweep3d's own translation of a scene into Mitsuba's (the OBJ/MTL reader, materials,
#: lights, the world, the filter) changes its pixels: part of every Mitsuba render key.
MITSUBA_TRANSLATION = 2  # 2: poses applied to the vertices, suns by their to_world (mitsuba/kept.py)
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


def cycles_only_defaults(engine: str) -> dict[str, Any]:
    """The Cycles-only settings at their defaults, for a spec rendering with ``engine`` that
    includes a Cycles spec (``realism score --engine``): nothing for Cycles itself."""
    if engine == "cycles":
        return {}
    from sweep3d.spec import RenderSpec

    return {name: RenderSpec.model_fields[name].default for name in CYCLES_ONLY}


def mitsuba_version() -> str:
    """The installed Mitsuba's version (a :class:`SpecError`-free empty string when it is missing:
    :func:`check_engine` refuses such a spec first)."""
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


def variant_note(engine: str) -> str | None:
    """The line a Mitsuba run says once when it renders with the slower ``scalar_rgb``."""
    if engine != "mitsuba" or mitsuba_variant() != "scalar_rgb":
        return None
    return ("the mitsuba engine renders with its scalar_rgb variant (no LLVM 19 library found): llvm_ad_rgb renders "
            "about 2.5x faster; install it with apt-get install libllvm19 (or set DRJIT_LIBLLVM_PATH)")


def engine_key(engine: str) -> dict[str, Any] | None:
    """The engine's part of every render key: None for Cycles (its keys stay as they were)."""
    if engine == "cycles":
        return None
    return {"name": engine, "version": mitsuba_version(), "variant": mitsuba_variant(),
            "translation": MITSUBA_TRANSLATION}


def plan_device(engine: str, device: str) -> str:
    """The device renders are keyed and made on: Mitsuba renders on the CPU whatever ``auto``
    finds (an explicit GPU is refused by :func:`check_engine`)."""
    return "cpu" if engine == "mitsuba" else device


def check_engine(spec: LoadedSpec) -> None:
    """Refuse, in one line naming the key and the engine, what the spec's engine cannot render.

    Raises:
        SpecError: Mitsuba is not installed, or the spec asks it for a GPU device, a mesh format
            it does not read (or a texture format), smoothing, part visibility, a Cycles-only
            setting (:data:`CYCLES_ONLY`) away from its default, or a control it cannot express.
    """
    engine = spec.render.engine
    if engine == "cycles":
        return
    path = str(spec.path)
    if not mitsuba_version():
        raise SpecError(path, "render.engine", "engine \"mitsuba\" needs the mitsuba package: pip install mitsuba")
    if spec.render.device in ("cuda", "optix"):
        raise SpecError(path, "render.device", f"device {spec.render.device!r} is Cycles'; the mitsuba engine "
                                               "renders on the CPU (use \"auto\" or \"cpu\")")
    if spec.report.part_visibility:
        raise SpecError(path, "report.part_visibility", "part visibility needs Cycles' UV pass; the mitsuba "
                                                        "engine cannot render it (set it false)")
    for name, what in CYCLES_ONLY.items():
        value = getattr(spec.render, name)
        if value != type(spec.render).model_fields[name].default:
            raise SpecError(path, f"render.{name}", f"{name} = {value!r} is a Cycles setting ({what}), so it "
                                                    f"would change nothing with engine \"mitsuba\"; remove it")
    for i, obj in enumerate(spec.objects):
        mesh = spec.meshes[obj.name]
        suffix = Path(str(mesh).partition("#")[2] or str(mesh)).suffix.lower()
        if suffix not in MITSUBA_MESHES:
            raise SpecError(path, f"objects[{i}].mesh", f"the mitsuba engine reads only .obj meshes (with their "
                                                        f"MTL), not {suffix or 'this file'}")
        for where, fmt in check_materials(mesh).base_textures:
            if fmt not in MITSUBA_FORMATS:
                raise SpecError(path, f"objects[{i}].mesh", f"{where}: a {fmt} texture, which the mitsuba engine "
                                                            f"cannot read (it reads {', '.join(sorted(MITSUBA_FORMATS))}); "
                                                            "save it as PNG and name that in the MTL")
        if obj.auto_smooth is not None:
            raise SpecError(path, f"objects[{i}].auto_smooth", "the mitsuba engine cannot smooth by angle; "
                                                               "remove auto_smooth")
    for index, inst in enumerate(spec.controls):
        if inst.control.stage != "render":
            continue
        problem = refused(inst.control, inst.spaces)
        if problem:
            raise SpecError(path, f"controls[{index}]", f"control {inst.control.type_name!r} (id "
                                                        f"{inst.control.id!r}): {problem} with engine \"mitsuba\"")


def refused(control: Any, spaces: dict[str, Any]) -> str | None:
    """Why the Mitsuba engine cannot render a rendered control with these parameter spaces (None: it can)."""
    name = control.type_name

    def can_be(param: str, test) -> bool:
        space = spaces.get(param)
        return space is not None and any(test(v) for v in space.values())

    if control.edits_scene:
        return "its edit() changes Blender's scene, which Mitsuba does not have"
    if name == "sky" and can_be("enabled", bool):
        return "Blender's procedural sky cannot be rendered"
    if name == "pin_to_ground" and can_be("enabled", bool):
        return "the ground is a Cycles shadow catcher, which cannot be rendered"
    if name == "material":
        if can_be("skin", lambda v: v != "original"):
            return "skins are Blender shader nodes and cannot be rendered"
        if can_be("emission", lambda v: v not in (None, 0, 0.0)):
            return "emission cannot be rendered"
    return None
