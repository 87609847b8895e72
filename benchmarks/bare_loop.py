"""A hand-written bpy render loop over a list of jobs: what a careful user would write without
sweep3d, the baseline that `benchmarks/pipeline.py --multi-scene` and `gpu.py` measure against.

Every mesh is imported once under its own empty (shown with hide_render), one world per
environment (scene.world), jobs world by world, object by object; render settings and framing
are sweep3d's, so both render the same pictures. It needs bpy and numpy alone (no sweep3d
install): the GPU benchmark runs it where only Blender is. A GPU is enabled by sweep3d's own
:func:`sweep3d.stages.render.cycles.gpus.enable`, loaded from this checkout by its path.

    python benchmarks/bare_loop.py JOBS.json FRAMES/ [--device cpu|cuda|optix]

JOBS.json is written by ``pipeline.bare_jobs``; paths in it are absolute or relative to its
folder. Prints one JSON line: set-up seconds, the first render's seconds (the device's kernels
load there), the loop's seconds (the first render included), the number of renders, peak RSS.
"""

import argparse
import importlib.util
import json
import math
import os
import resource
import sys
import time
from pathlib import Path

GPUS = Path(__file__).resolve().parents[1] / "sweep3d" / "stages" / "render" / "cycles" / "gpus.py"


def use_gpu(bpy, scene, device: str) -> None:
    """Render on ``device``'s GPUs ("cuda", "optix") as a sweep3d worker does, or exit 2."""
    module_spec = importlib.util.spec_from_file_location("sweep3d_gpus", GPUS)
    gpus = importlib.util.module_from_spec(module_spec)
    module_spec.loader.exec_module(gpus)
    if not gpus.enable(bpy, scene, device.upper()):
        sys.exit(f"bare_loop: Cycles finds no {device} GPU here")


def main() -> None:
    t0 = time.perf_counter()
    parser = argparse.ArgumentParser()
    parser.add_argument("jobs", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda", "optix"])
    args = parser.parse_args()
    import bpy
    import numpy as np
    from mathutils import Matrix

    spec, out, base = json.loads(args.jobs.read_text()), str(args.out), args.jobs.resolve().parent
    args.out.mkdir(parents=True, exist_ok=True)
    s = spec["settings"]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device, c.samples, c.use_adaptive_sampling, c.seed = "CPU", s["samples"], False, s["seed"]
    if args.device != "cpu":
        use_gpu(bpy, scene, args.device)
    c.use_denoising, c.denoiser, c.denoising_prefilter = True, "OPENIMAGEDENOISE", "FAST"
    c.max_bounces = s["max_bounces"]
    r = scene.render
    r.resolution_x = r.resolution_y = s["size"]
    r.resolution_percentage = 100
    lo, hi = (s["size"] - s["crop"]) // 2 + 0.25, (s["size"] - s["crop"]) // 2 + s["crop"] + 0.25
    r.use_border = r.use_crop_to_border = True
    r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = (lo / s["size"], hi / s["size"]) * 2
    r.use_persistent_data = True
    r.threads_mode, r.threads = "FIXED", os.cpu_count()
    scene.view_settings.view_transform = "Standard"
    r.image_settings.file_format, r.image_settings.color_mode, r.image_settings.compression = "PNG", "RGBA", 0

    def load(path):  # under a pose empty, normalised to a unit bounding sphere at the origin
        before = set(bpy.data.objects)
        bpy.ops.wm.obj_import(filepath=str(base / path))
        new = [o for o in bpy.data.objects if o not in before]
        meshes = [o for o in new if o.type == "MESH"]
        pts = []
        for o in meshes:
            co = np.empty(len(o.data.vertices) * 3)
            o.data.vertices.foreach_get("co", co)
            m = np.array(o.matrix_world)
            pts.append(co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])
        pts = np.concatenate(pts)
        centre = (pts.min(0) + pts.max(0)) / 2
        radius = float(np.sqrt(((pts - centre) ** 2).sum(1).max()))
        pose = bpy.data.objects.new("pose", None)
        norm = bpy.data.objects.new("norm", None)
        for empty in (pose, norm):
            scene.collection.objects.link(empty)
        norm.parent, norm.scale, norm.location = pose, (1 / radius,) * 3, tuple(-centre / radius)
        for o in new:
            if o.parent is None:
                o.parent = norm
        return pose, meshes

    def world(env):
        w = bpy.data.worlds.new("w")
        w.use_nodes = True
        bg = w.node_tree.nodes["Background"]
        if env["hdri"]:
            tex = w.node_tree.nodes.new("ShaderNodeTexEnvironment")
            tex.image = bpy.data.images.load(str(base / env["hdri"]))
            w.node_tree.links.new(tex.outputs["Color"], bg.inputs["Color"])
        else:
            bg.inputs["Color"].default_value = (*env["color"], 1.0)
        bg.inputs["Strength"].default_value = env["strength"] * env["fill"]
        return w

    objects = {path: load(path) for path in spec["meshes"]}
    worlds = {name: world(env) for name, env in spec["environments"].items()}
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    cam.data.sensor_fit, cam.data.sensor_width, cam.data.lens = "HORIZONTAL", 36.0, 50.0
    scene.collection.objects.link(cam)
    scene.camera = cam
    d = 1 / (0.8 * math.sin(math.atan(18 / 50)))
    t1 = time.perf_counter()
    devnull = os.open(os.devnull, os.O_WRONLY)
    saved = os.dup(1)
    os.dup2(devnull, 1)
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    scene.collection.objects.link(sun)
    shown, first = None, None
    for job in spec["jobs"]:  # world by world, object by object
        if scene.world != worlds[job["environment"]]:
            scene.world = worlds[job["environment"]]
        if job["mesh"] != shown:
            for path, (_, meshes) in objects.items():
                for o in meshes:
                    o.hide_render = path != job["mesh"]
            shown = job["mesh"]
        objects[job["mesh"]][0].rotation_euler = (0.0, 0.0, math.radians(job["yaw"]))
        e = math.radians(job["elevation"])
        cam.location = (0.0, -d * math.cos(e), d * math.sin(e))
        cam.rotation_euler = (math.pi / 2 - e, 0.0, 0.0)
        r.film_transparent = job["sun"] is not None  # a plain colour is put behind afterwards, as sweep3d does
        sun.hide_render = job["sun"] is None  # a plain colour's key light, riding with the camera
        if job["sun"] is not None:
            sun.data.energy, sun.data.angle = job["sun"]["energy"], job["sun"]["angle"]
            sun.matrix_world = Matrix(job["sun"]["matrix"])
        r.filepath = f"{out}/{job['key']}.png"
        bpy.ops.render.render(write_still=True)
        if first is None:
            first = time.perf_counter() - t1
    os.dup2(saved, 1)
    t2 = time.perf_counter()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"setup": t1 - t0, "first": first, "loop": t2 - t1, "n": len(spec["jobs"]),
                      "peak_mb": peak, "device": args.device}))


if __name__ == "__main__":
    main()
