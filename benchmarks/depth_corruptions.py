"""The depth-aware post controls (``fog``, ``defocus``) against Blender rendering the same effect.

Per scene, one pinhole render with its depth pass, then the post controls on it; and the same
effect rendered by Cycles:

- defocus: the ``camera`` control's ``fstop`` (Cycles' thin-lens depth of field, focused on the
  object's centre, the same aperture and focus the post control uses);
- fog: a homogeneous medium of absorption β and emission β · A (linear airlight A) in a sphere
  around the camera, seen by camera rays only (no shadow or indirect rays). Along a camera ray
  it renders exactly I = J e^(-β d) + A (1 - e^(-β d)), the fog model, with Cycles' own
  sub-pixel rays and distances; the surfaces stay lit as without fog (what Koschmieder's model
  assumes). The sphere's radius is the post control's ``background_distance``: 500 radii for the
  default (fully fogged background at these densities).

Each configuration's error is against its physical render: PSNR over the whole image and the mean
absolute difference in 8-bit levels; the pinhole render against the physical one is the no-effect
baseline (how much the effect changes the image). Times: the post control's ``apply`` per image
(median of 5) against the physical render's (without the scene load; the same samples and
denoiser as the pinhole render). Renders are 160², 32 samples + OpenImageDenoise, 2 threads.

    .venv/bin/python benchmarks/depth_corruptions.py [--size 160] [--samples 32] [--image docs/images/depth_corruptions.png]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENES = [  # (object of specs/quickstart.toml, HDRI, camera azimuth, elevation, zoom)
    ("reflex camera", "studio", 35.0, 15.0, 1.2),
    ("cheeseburger", "courtyard", -30.0, 25.0, 1.0),
    ("toaster", "interior", 60.0, 10.0, 1.3),
]
AIRLIGHT = "#cccccc"
FULLY_FOGGED = 500.0  # the medium's radius standing for an infinitely far background
CONFIGS = [  # (name, post control, its values, what the physical render changes)
    ("defocus f/0.4", "defocus", {"fstop": 0.4}, {"fstop": 0.4}),
    ("defocus f/0.15", "defocus", {"fstop": 0.15}, {"fstop": 0.15}),
    ("fog 0.15", "fog", {"density": 0.15, "color": AIRLIGHT}, {"density": 0.15, "radius": FULLY_FOGGED}),
    ("fog 0.4", "fog", {"density": 0.4, "color": AIRLIGHT}, {"density": 0.4, "radius": FULLY_FOGGED}),
    ("fog 0.4, background at 8", "fog", {"density": 0.4, "color": AIRLIGHT, "background_distance": 8.0},
     {"density": 0.4, "radius": 8.0}),
]


#: The (scene, effect) pairs of the side-by-side image, one row each.
PICTURED = [("toaster", "defocus f/0.15"), ("cheeseburger", "fog 0.4"), ("reflex camera", "defocus f/0.15")]


def fog_volume_control():
    """A rendered control whose ``edit`` fills a sphere around the camera with the fog medium."""
    from pydantic import Field

    from sweep3d.core.control import ControlParams
    from sweep3d.stages.postprocess.controls.depth import airlight
    from sweep3d.stages.render.controls import RenderedControl

    class FogVolume(RenderedControl):
        order = 90

        class Params(ControlParams):
            density: float = Field(0.0, ge=0.0)
            radius: float = Field(FULLY_FOGGED, gt=0.0)
            color: str = AIRLIGHT

        def apply(self, state, params) -> None:
            pass

        def edit(self, scene, params) -> None:
            if params.density == 0:
                return
            bpy = scene.bpy
            mesh = bpy.data.meshes.new("fog_domain")
            import bmesh  # noqa: PLC0415  (ships with bpy)

            shape = bmesh.new()
            bmesh.ops.create_uvsphere(shape, u_segments=64, v_segments=32, radius=params.radius)
            shape.to_mesh(mesh)
            shape.free()
            domain = bpy.data.objects.new("fog_domain", mesh)
            for ray in ("diffuse", "glossy", "transmission", "volume_scatter", "shadow"):
                setattr(domain, f"visible_{ray}", False)  # camera rays only: the surfaces stay lit as without fog
            material = bpy.data.materials.new("fog_medium")
            material.use_nodes = True
            nodes, links = material.node_tree.nodes, material.node_tree.links
            nodes.clear()
            out = nodes.new("ShaderNodeOutputMaterial")
            absorb = nodes.new("ShaderNodeVolumeAbsorption")
            absorb.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)  # absorption coefficient = density
            absorb.inputs["Density"].default_value = params.density
            glow = nodes.new("ShaderNodeEmission")  # in a volume: radiance per unit length
            glow.inputs["Color"].default_value = (*airlight(params.color).tolist(), 1.0)
            glow.inputs["Strength"].default_value = params.density  # emission / absorption = the airlight
            both = nodes.new("ShaderNodeAddShader")
            links.new(absorb.outputs[0], both.inputs[0])
            links.new(glow.outputs[0], both.inputs[1])
            links.new(both.outputs[0], out.inputs["Volume"])
            mesh.materials.append(material)
            scene.add(domain, parent=scene.camera)  # centred on the camera: every ray crosses `radius` of it

    return FogVolume("fog_volume", "fog_volume")


def _render(mesh_by_object: dict[str, str], size: int, samples: int, physical: bool, out) -> None:
    """In a fresh process: per scene the pinhole render (with its depth pass; ``physical`` False)
    or each configuration's physical render; sends back images, depths, frames and seconds."""
    from sweep3d.assets.sources import builtin_hdris
    from sweep3d.core.pixels import decode_png
    from sweep3d.core.truth import decode_depth
    from sweep3d.stages.postprocess.frame import frame_from_state
    from sweep3d.stages.render.controls import RENDERED_CONTROLS
    from sweep3d.stages.render.cycles.scene import BlenderScene
    from sweep3d.stages.render.worker import posed_state, render_job
    from sweep3d.stages.render.worker_protocol import EnvironmentRef, RenderJob, RenderSettings

    scratch = Path(tempfile.mkdtemp(prefix="depth-bench-"))
    quiet = os.open(os.devnull, os.O_WRONLY)
    os.dup2(quiet, 1)  # Blender prints its progress to file descriptor 1; results go through the pipe
    scene = BlenderScene(RenderSettings(resolution=size, samples=samples, denoise=True, threads=2,
                                        passes=() if physical else ("depth", "mask")), scratch)
    camera = RENDERED_CONTROLS.get("camera")("camera", "camera")
    volume = fog_volume_control()
    hdris = builtin_hdris()
    results = []
    for obj, hdri, azimuth, elevation, zoom in SCENES:
        view = {"azimuth": azimuth, "elevation": elevation, "zoom": zoom}
        wanted = [(name, changes) for name, _, _, changes in CONFIGS] if physical else [("pinhole", {})]
        wanted = [("warm-up", {})] + wanted  # the scene load, left out of the times
        for name, changes in wanted:
            fstop = changes.get("fstop", 0.0)
            controls = [(camera, camera.params({**view, "fstop": fstop}))]
            if "density" in changes:
                controls.append((volume, volume.Params(density=changes["density"], radius=changes["radius"])))
            job = RenderJob(f"{obj}-{name}", mesh_by_object[obj], EnvironmentRef(hdri=str(hdris[hdri])),
                            tuple(controls), blob=str(scratch / "frame.png"))
            reply = render_job(scene, job)
            assert reply.ok, reply.error
            image = decode_png(scratch / "frame.png")
            depth = decode_depth(reply.truth["depth"]) if reply.truth and "depth" in reply.truth else None
            frame = frame_from_state(posed_state(job), size, None, depth, None)
            results.append((obj, name, image, frame, reply.info.render_seconds))
    out.send(results)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(1.0 / mse)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=160)
    parser.add_argument("--samples", type=int, default=32)
    parser.add_argument("--image", type=Path, default=None, help="write a side-by-side PNG (post | physical) here")
    args = parser.parse_args()
    import sweep3d
    from sweep3d.assets.sources import materialise_mesh
    from sweep3d.runner import builtin_catalogue as catalogue

    folder = Path(tempfile.mkdtemp(prefix="depth-bench-"))
    spec = sweep3d.load(REPO / "specs" / "quickstart.toml").spec
    meshes = {obj: str(materialise_mesh(spec.meshes[obj], folder)) for obj, *_ in SCENES}
    print(f"{len(SCENES)} scenes at {args.size}², {args.samples} samples + OpenImageDenoise, 2 threads; "
          f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    ctx = mp.get_context("spawn")
    found = {}
    for physical in (False, True):
        here, there = ctx.Pipe()
        proc = ctx.Process(target=_render, args=(meshes, args.size, args.samples, physical, there))
        proc.start()
        found.update({(obj, name): rest for obj, name, *rest in here.recv()})
        proc.join()
    controls = {name: catalogue().controls.get(name)(name, name) for name in ("fog", "defocus")}
    rows: dict[str, list[tuple[float, float, float, float, float]]] = {name: [] for name, *_ in CONFIGS}
    tiles = []
    for obj, *_ in SCENES:
        pinhole, frame, _ = found[obj, "pinhole"]
        for name, control, values, _ in CONFIGS:
            physical, _, physical_seconds = found[obj, name]
            c = controls[control]
            params = c.params(values)
            times = []
            for _ in range(5):
                started = time.perf_counter()
                post = c.apply(pinhole, params, np.random.default_rng(0), frame)
                times.append(time.perf_counter() - started)
            rows[name].append((psnr(post, physical), 255 * float(np.abs(post - physical).mean()),
                               psnr(pinhole, physical), statistics.median(times), physical_seconds))
            if (obj, name) in PICTURED:
                tiles.append((obj, name, post, physical))
    scenes = " / ".join(obj for obj, *_ in SCENES)
    print(f"| effect | PSNR post vs physical, dB ({scenes}) | mean abs. diff. (8-bit levels) "
          "| PSNR pinhole vs physical (no effect) | post s/image | physical render s/image |")
    print("|---|---|---|---|---|---|")
    for name, measured in rows.items():
        cols = list(zip(*measured))
        print(f"| {name} | {' / '.join(f'{v:.1f}' for v in cols[0])} "
              f"| {statistics.mean(cols[1]):.1f} | {statistics.mean(cols[2]):.1f} "
              f"| {statistics.median(cols[3]):.3f} | {statistics.median(cols[4]):.2f} |")
    pinhole_seconds = statistics.median(found[obj, "pinhole"][2] for obj, *_ in SCENES)
    print(f"pinhole render with its depth pass: {pinhole_seconds:.2f} s/image (median over the scenes)")
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    if args.image is not None:
        _side_by_side(args.image, sorted(tiles, key=lambda t: PICTURED.index(t[:2])))


def _side_by_side(path: Path, tiles: list[tuple[str, str, np.ndarray, np.ndarray]]) -> None:
    """One row per effect: post-processed | physical render."""
    from PIL import Image

    from sweep3d.core.pixels import to_uint8

    gap = 4
    rows = [np.concatenate([post, np.ones((post.shape[0], gap, 3), np.float32), physical], axis=1)
            for _, _, post, physical in tiles]
    sheet = np.concatenate([r for row in rows for r in (row, np.ones((gap, row.shape[1], 3), np.float32))][:-1], axis=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(to_uint8(sheet), "RGB").quantize(256).save(path, optimize=True)  # 256 colours: a third of the bytes
    print(f"wrote {path} (rows: {', '.join(f'{t[0]}, {t[1]}' for t in tiles)}; left: post control, right: Cycles)")


if __name__ == "__main__":
    main()
