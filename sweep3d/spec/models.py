"""Pydantic models of the TOML spec. Every default lives here; every model forbids unknown keys."""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

from sweep3d.core import Typed, printable

Name = Annotated[str, Field(min_length=1, max_length=200), AfterValidator(printable)]


class StrictModel(Typed):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ExperimentSpec(StrictModel):
    name: Name = Field(description="Shown in the report; names the run's jobs table.")
    seed: int = Field(0, ge=0, le=2**63 - 1, description="Drives random policies and noise.")
    store: str = Field(".sweep3d", description="Content-addressed store; relative to the spec file.")
    max_jobs: int = Field(1_000_000, ge=1, description="Refuse a spec that expands to more jobs (counted before "
                                                       "any is made); raise it for a bigger sweep.")
    max_archive_mb: float = Field(256.0, gt=0, allow_inf_nan=False,
                                  description="The most megabytes (10^6 bytes) a file of a mesh archive may expand "
                                              "to: a small zip can hold a huge file that would fill the store.")

    @field_validator("store")
    @classmethod
    def _names_a_folder(cls, store: str) -> str:
        """An empty path would make the spec's own folder the store, filling it with blobs and tables."""
        if not store.strip():
            raise ValueError("must name the store's folder (relative to the spec file), e.g. \".sweep3d\"; "
                             "an empty path would make the spec's own folder the store")
        return store


#: The built-in renderers (Cycles first: the default and the bench's reference). ``[render] engine``
#: is checked against the catalogue's engines (``stages.render.BACKENDS``), which a test keeps equal.
ENGINES: tuple[str, ...] = ("cycles", "mitsuba")


class RenderSpec(StrictModel):
    resolution: int | Literal["model"] = Field(
        224, description="Square image side in pixels, or 'model': render exactly the model's input "
                         "(the centre crop of a frame of its resize size), which it then does not resample.")
    samples: int = Field(4, ge=1, le=65536, description="Cycles samples per pixel.")
    denoise: bool = True
    denoise_prefilter: Literal["fast", "accurate", "none"] = "fast"
    max_bounces: int = Field(8, ge=0, le=1024)
    adaptive_threshold: float = Field(0.0, ge=0.0, le=1.0, allow_inf_nan=False,
                                      description="Cycles adaptive sampling noise threshold; 0 = off.")
    seed: int = Field(0, ge=0, le=2**31 - 1, description="Cycles sampling seed.")
    threads: int = Field(0, ge=0, le=1024, description="Cycles threads per worker; 0 = all cores.")
    workers: int = Field(1, ge=1, le=256, description="Render worker processes.")
    timeout: float = Field(600.0, gt=0, description="Seconds one render may take before it fails (tried twice).")
    edit_timeout: float = Field(60.0, gt=0, description="Seconds a rendered control's edit() may take in one job; "
                                                        "past it the run stops with a line naming the control.")
    device: Literal["auto", "cpu", "cuda", "optix"] = Field(
        "auto", description="Cycles' device: auto (OptiX, else CUDA, else the CPU), cpu, or an NVIDIA GPU through "
                            "cuda or optix. A GPU's renders are keyed apart (GPU Cycles does not give CPU's pixels).")
    worker_memory: int = Field(4096, ge=0, le=2**22, description="MB of resident memory a render worker may hold "
                               "after a job before it is replaced by a fresh one (between jobs); 0 = no limit.")
    worker_jobs: int = Field(0, ge=0, le=10**9, description="Replace a render worker by a fresh one after this "
                                                            "many jobs (at most 10^9: more than any run makes); "
                                                            "0 = never.")
    dither: float = Field(1.0, ge=0.0, le=10.0, allow_inf_nan=False,
                          description="Blender's scene.render.dither_intensity: noise added before the 8-bit "
                                      "quantisation (Blender's default 1.0; 0 = none). Keyed only when not 1.0.")
    world_sampling: Literal["automatic", "manual", "none"] = Field(
        "automatic", description="How Cycles importance-samples the world (an HDRI): Blender's world "
                                 "sampling_method. 'manual' uses world_map_resolution. Keyed only when not automatic.")
    world_map_resolution: int = Field(1024, ge=4, le=16384,
                                      description="The world's importance map side with world_sampling = 'manual' "
                                                  "(Blender's sample_map_resolution).")
    engine: str = Field(
        "cycles", description="The renderer: \"cycles\" (Blender's Cycles), or \"mitsuba\" (Mitsuba 3: a second "
                              "renderer, to tell a model's failure from a simulator artifact; "
                              "docs/how-to/second-renderer.md). Keyed apart.")

    @field_validator("resolution", mode="before")
    @classmethod
    def _pixels_or_model(cls, value: Any) -> Any:
        """One clear line instead of pydantic's two union branches."""
        if value == "model" or (isinstance(value, int) and not isinstance(value, bool) and 8 <= value <= 4096):
            return value
        raise ValueError(f"must be a square image side of 8..4096 pixels or \"model\" (the model's input "
                         f"size, which it then does not resample); got {value!r}")

    @field_validator("timeout", "edit_timeout")
    @classmethod
    def _finite(cls, value: float) -> float:
        if not math.isfinite(value):
            raise ValueError("must be a finite number of seconds")
        return value

    def key_part(self, pixels: dict[str, int], device: str = "cpu") -> dict[str, Any]:
        """Settings that change pixels (threads, workers and their recycling do not).

        Args:
            pixels: the resolved frame (``Framing.key_part()``): "model" is never hashed as such,
                so a model-framed render and a full-frame one cannot share a key. New settings at
                their neutral value are left out, so older keys stay valid.
            device: the device renders are made on, ``device`` resolved (``"auto"`` never is
                hashed: see ``stages.render.device``); only a GPU is in the key, so CPU renders
                keep the keys they had before the setting existed.
        """
        part = self.model_dump(exclude={"threads", "workers", "timeout", "edit_timeout", "resolution",
                                        "adaptive_threshold", "seed", "device", "worker_memory", "worker_jobs",
                                        "dither", "world_sampling", "world_map_resolution",
                                        "engine"})  # the engine keys apart: render/keys.py
        part.update(pixels)
        if device != "cpu":
            part["device"] = device
        part.update({k: v for k in ("adaptive_threshold", "seed") if (v := getattr(self, k))})
        if self.dither != 1.0:  # Blender's default: keys of specs that do not set it stay as they were
            part["dither"] = self.dither
        if self.world_sampling != "automatic":
            part["world_sampling"] = self.world_sampling
            if self.world_sampling == "manual":
                part["world_map_resolution"] = self.world_map_resolution
        return part


class ModelSpec(StrictModel):
    name: str = Field("efficientnet-lite0", description="A built-in model or 'module:factory'.")
    id: Name | None = Field(None, description="What results call this model (their `model` column); "
                                              "default: its name. Needed when two entries share a name.")
    backend: Literal["torch", "onnx"] = Field("torch", description="onnx: ONNX Runtime, checked against torch.")
    batch_size: int = Field(32, ge=1, le=4096)
    threads: int = Field(0, ge=0, le=1024, description="torch threads; 0 = all cores.")
    resize_arithmetic: Literal["float", "uint8"] = Field(
        "float", description="How the model's bilinear resize computes: 'float' (on the float image, sweep3d's "
                             "default) or 'uint8' (on 8-bit pixels, rounded back to 8 bits, as PIL and torchvision "
                             "on PIL images do). In the prediction key only when not 'float'.")

    @property
    def label(self) -> str:
        """The model's name in results: its ``id``, else its ``name``."""
        return self.id or self.name


class EvaluatorSpec(Typed):
    """``kind`` picks the evaluator; ``passes`` and ``min_visible`` are every evaluator's; the other
    keys are the evaluator's own settings, checked against its ``Params`` when the spec loads
    (``top_k`` for classification, ``iou`` and ``score`` for detection, …)."""

    model_config = ConfigDict(extra="allow", frozen=True)
    kind: str = Field("classification", description="classification | localization | detection | segmentation, "
                                                     "or 'package.module:Class' for your own.")
    passes: list[Literal["mask", "depth"]] = Field(
        default_factory=list, description="Ground-truth passes to render beside the image: the object's visible "
                                          "mask (with its box and visible fraction) and depth. Not in the render key.")
    min_visible: float = Field(
        0.1, ge=0.0, le=1.0, description="A job whose object shows less than this share of its unoccluded, "
                                         "unclipped silhouette is not evaluable (needs the mask pass).")

    @property
    def params(self) -> dict[str, Any]:
        """The evaluator's own settings, as the spec gives them (its ``Params`` fills the rest)."""
        return dict(self.model_extra or {})


def _unit(low: float = 0.0, high: float = 1.0, what: str = "") -> Any:
    return Field(None, ge=low, le=high, allow_inf_nan=False, description=what)


class MaterialSpec(StrictModel):
    """Principled BSDF inputs set on an object's materials; a value left out keeps the file's
    (as Blender's importer made it: ``sweep3d plan --materials`` shows both)."""

    base_color: tuple[float, float, float] | None = Field(None, description="Linear RGB, 0..1 each.")
    opacity: float | None = _unit(what="Alpha: 1 opaque, 0 invisible (an MTL's `d`).")
    roughness: float | None = _unit()
    metallic: float | None = _unit()
    transmission: float | None = _unit(what="Transmission weight: 1 is glass (an MTL's `Tf`).")
    ior: float | None = _unit(1.0, 4.0, "Index of refraction (an MTL's `Ni`).")
    coat: float | None = _unit(what="Coat weight (Blender's OBJ importer sets a quarter of an MTL's `Pc`).")

    @field_validator("base_color")
    @classmethod
    def _unit_color(cls, color: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if color is not None and not all(math.isfinite(c) and 0.0 <= c <= 1.0 for c in color):
            raise ValueError(f"base_color components must be finite numbers between 0 and 1, got {list(color)}")
        return color

    def key_part(self) -> dict[str, Any]:
        """The values given, by name (what the render key holds; empty: no override)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in self.model_dump(exclude_none=True).items()}


class ObjectSpec(StrictModel):
    name: Name
    mesh: str = Field(description="OBJ/glTF/GLB/PLY/STL path, or 'archive.zip#member.obj'.")
    labels: list[int | str] = Field(min_length=1, description="ImageNet class names or ids.")
    parts: list[Name] | None = Field(None, min_length=1, description="Render (and frame) only these objects of the "
                                     "mesh file, by name (an object's descendants come with it).")
    material: MaterialSpec | None = Field(None, description="Overrides on every material of the rendered parts.")
    materials: dict[Name, MaterialSpec] = Field(default_factory=dict, description="Overrides per material name, "
                                                "on top of `material`.")
    auto_smooth: float | None = Field(None, gt=0.0, le=180.0, allow_inf_nan=False,
                                      description="Shade smooth, with edges sharper than this angle (degrees) kept "
                                                  "sharp; replaces the file's own normals.")

    @field_validator("parts")
    @classmethod
    def _distinct_parts(cls, parts: list[str] | None) -> list[str] | None:
        if parts is not None and len(set(parts)) < len(parts):
            twice = next(p for i, p in enumerate(parts) if p in parts[:i])
            raise ValueError(f"part {twice!r} is listed twice; list each object once")
        return parts

    def look_key(self) -> dict[str, Any] | None:
        """What the object's parts, material overrides and smoothing add to its render key; None
        when nothing is given (or only empty overrides), so keys stay as they were before them."""
        look: dict[str, Any] = {}
        if self.parts:
            look["parts"] = sorted(self.parts)
        if self.material is not None and self.material.key_part():
            look["material"] = self.material.key_part()
        named = {name: m.key_part() for name, m in self.materials.items() if m.key_part()}
        if named:
            look["materials"] = named
        if self.auto_smooth is not None:
            look["auto_smooth"] = self.auto_smooth
        return look or None

    @field_validator("labels", mode="before")
    @classmethod
    def _names_or_ids(cls, labels: Any) -> Any:
        """Refuse what pydantic would coerce: ``true`` would silently become class 1, 2.0 class 2."""
        for i, label in enumerate(labels if isinstance(labels, list) else []):
            if isinstance(label, bool) or not isinstance(label, (int, str)):
                raise ValueError(f"labels[{i}] = {label!r} is not a class name or id; give an ImageNet class "
                                 "name such as \"coffee mug\" or an integer id 0..999")
            if isinstance(label, str):
                printable(label)
        return labels


class KeyLightSpec(StrictModel):
    """The key light of a plain-colour environment: a neutral white sun, riding with the camera by
    default, with the plain world's uniform light dimmed to ``fill``, so an object has a lit and a
    shaded side instead of washing out (a white mug on white). Both scale with the environment's
    strength. Its angles are the ``sun_light`` control's, in the frame ``relative_to`` names."""

    strength: float = Field(2.5, gt=0, le=1e6, allow_inf_nan=False,
                            description="The sun's irradiance in W/m² at environment strength 1.")
    azimuth: float = Field(-40.0, ge=-180.0, le=180.0, allow_inf_nan=False,
                           description="Degrees, > 0 toward the image's right (-40: camera left) relative to the "
                                       "camera; relative to the world, the camera control's azimuth (0 in front, "
                                       "90 the object's +X side).")
    elevation: float = Field(45.0, ge=-90.0, le=90.0, allow_inf_nan=False,
                             description="Degrees up: toward the image's top (camera) or above the horizon (world).")
    angle: float = Field(10.0, ge=0.0, le=180.0, allow_inf_nan=False,
                         description="The sun's angular diameter in degrees: larger, softer shadows.")
    fill: float = Field(0.4, ge=0.0, le=1.0, allow_inf_nan=False,
                        description="What share of the plain world's light stays, as fill.")
    relative_to: Literal["camera", "world"] = Field(
        "camera", description="'camera': it moves with the camera and lights the same side of every image; "
                              "'world': it stays put while the camera goes round.")

    def key_part(self) -> dict[str, Any]:
        """Its part of a render key: riding with the camera (the default) keys as before the choice existed."""
        return self.model_dump(exclude={"relative_to"} if self.relative_to == "camera" else set())


class EnvironmentSpec(StrictModel):
    name: Name
    hdri: str | None = Field(None, description="'builtin:NAME' or an .exr/.hdr/.png path.")
    color: tuple[float, float, float] | None = Field(None, description="Plain background, RGB 0..1.")
    strength: float = Field(1.0, gt=0, le=1e6, allow_inf_nan=False,
                            description="Multiplies the world's light: the HDRI's radiance, or a plain colour's "
                                        "uniform white light (radiance 1 at strength 1) and its key light.")
    key_light: KeyLightSpec | None = Field(None, description="A plain colour's key light: true (the default for "
                                           "a colour), false, or a table of KeyLightSpec's keys.")

    @model_validator(mode="before")
    @classmethod
    def _key_light(cls, data: Any) -> Any:
        """``key_light`` is on for a plain colour unless ``false``; ``true`` means the defaults."""
        if not isinstance(data, dict):
            return data
        key = data.get("key_light", "color" in data)
        if key is True:
            key = {}
        elif key is False:
            key = None
        elif not isinstance(key, dict):
            raise ValueError(f"key_light must be true, false or a table such as {{ strength = 2.5, azimuth = -40 }}; "
                             f"got {key!r}")
        return {**data, "key_light": key}

    @field_validator("color")
    @classmethod
    def _unit_color(cls, color: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if color is not None:
            for c in color:
                if not (math.isfinite(c) and 0.0 <= c <= 1.0):
                    raise ValueError(f"color components must be between 0 and 1, got {list(color)}")
        return color

    @model_validator(mode="after")
    def _one_background(self) -> EnvironmentSpec:
        if (self.hdri is None) == (self.color is None):
            raise ValueError("give exactly one of hdri = '...' or color = [r, g, b]")
        if self.hdri is not None and self.key_light is not None:
            raise ValueError("key_light is for a plain colour environment (color = [r, g, b]); light an HDRI "
                             "with a sun_light or area_light control")
        return self

    def key_part(self, hdri_digest: str | None) -> dict[str, Any]:
        """The environment's part of a render key (the HDRI by content); no key light, no entry,
        so keys made before key lights existed stay valid for ``key_light = false``."""
        part: dict[str, Any] = {"hdri": hdri_digest, "color": list(self.color) if self.color else None,
                                "strength": self.strength}
        if self.key_light is not None:
            part["key_light"] = self.key_light.key_part()
        return part


class ReportSpec(StrictModel):
    part_visibility: bool = Field(
        False, description="Add the part-visibility panel: renders a UV pass and records which parts of "
                           "each object every image shows (decided before rendering; a later switch re-renders "
                           "for the pass only and re-infers nothing).")


class AggregateSpec(StrictModel):
    drop_fragile: bool = Field(
        False, description="Leave fragile results (near-ties that the stability check saw flip under changes no "
                           "eye sees; `sweep3d stability`) out of what is counted: failure modes, boundaries and "
                           "accuracies. Without a check, nothing is left out.")


class StabilitySpec(StrictModel):
    """``sweep3d stability``'s scene neighbours: the changes to a sampled job's scene a person would
    call invisible (each rendered parameter the spec varies, both ways; see ``neighbour_steps``)."""

    scene: bool = Field(True, description="Re-render each sampled job's neighbours (each varied rendered parameter "
                                          "moved both ways by the steps below) beside the image changes.")
    angle: float = Field(1.0, gt=0.0, le=45.0, allow_inf_nan=False,
                         description="Degrees an angle of the object, the camera or a light moves.")
    distance: float = Field(0.01, gt=0.0, le=0.5, allow_inf_nan=False,
                            description="Share the camera's distance moves (0.01: 1 % nearer and farther).")
    light: float = Field(0.05, gt=0.0, le=0.5, allow_inf_nan=False,
                         description="Share a light's strength (an HDRI's too) moves (0.05: 5 % weaker and stronger).")
    hdri_rotation: float = Field(2.0, gt=0.0, le=45.0, allow_inf_nan=False,
                                 description="Degrees the environment map turns.")


class PostprocessSpec(StrictModel):
    store: Literal["all", "none"] = Field(
        "none", description="Which post-processed images are written to the store: 'none' makes each in "
                            "memory for inference and writes it only where it is looked at (the report, "
                            "export), made again from its render; 'all' writes every one as it is made. "
                            "Keys and answers are the same either way.")
    workers: int = Field(0, ge=0, le=1024, description="Post-processing worker processes at most; 0 = one per core "
                         "(os.cpu_count()), 1 = none (the run's own process makes every image). Workers start only "
                         "when the images waiting would take more than about a second here; in no key: an image's "
                         "bytes are the same wherever it is made.")


class PolicySpec(Typed):
    """``type`` picks the policy; ``paired`` is the planner's; the other keys are the policy's parameters."""

    model_config = ConfigDict(extra="allow", frozen=True)
    type: str = "grid"
    paired: bool | Literal["all"] = Field(
        False, description="Draw the controls from (seed, object, control id), not per scene, so every environment "
                           "of an object gets the same points (\"all\": every object too); for paired statistics.")

    cross: dict[str, int | None] = Field(
        default_factory=dict,
        description="Listed values crossed with the policy's draws instead of drawn per job: \"<control id>.<param>\" "
                    "(every value on every draw; a number k in a table: on the first k draws only, the other draws "
                    "keeping the first listed value), \"environment\" (the same draws in every environment: "
                    "paired = true) and \"object\" (every object too: paired = \"all\").")

    @field_validator("paired", mode="before")
    @classmethod
    def _paired_word(cls, value: Any) -> Any:
        """Only the TOML booleans or "all": pydantic would read "yes" or 1 as true."""
        if value is True or value is False or value == "all":
            return value
        raise ValueError(f'must be true, false or "all" (got {value!r})')

    @field_validator("cross", mode="before")
    @classmethod
    def _cross_table(cls, value: Any) -> Any:
        """A list names what is crossed with every draw; a table may limit a list to the first k draws."""
        if isinstance(value, str):
            value = [value]
        if isinstance(value, list) and all(isinstance(v, str) for v in value):
            value = dict.fromkeys(value, True)
        if not isinstance(value, dict):
            raise ValueError('must be a list such as ["environment", "material.skin"] or a table such as '
                             f'{{ environment = true, "material.skin" = 5 }}; got {value!r}')
        out: dict[str, int | None] = {}
        for name, k in value.items():
            if k is True:
                out[name] = None
            elif isinstance(k, int) and not isinstance(k, bool) and k >= 1 and name not in ("environment", "object"):
                out[name] = k
            else:
                what = "true" if name in ("environment", "object") else "true (every draw) or a number k >= 1 (the first k draws)"
                raise ValueError(f"{name!r} = {k!r}: give {what}")
        return out

    @model_validator(mode="after")
    def _cross_scenes(self) -> PolicySpec:
        """Crossing the environment (object) is what ``paired`` does: the two say it once."""
        wanted = "all" if "object" in self.cross else True if "environment" in self.cross else self.paired
        if wanted != self.paired and "paired" in self.model_fields_set and not (wanted is True and self.paired == "all"):
            toml = '"all"' if wanted == "all" else "true"
            raise ValueError(f"cross names {'object' if wanted == 'all' else 'environment'}, which is paired = "
                             f"{toml}; remove paired or make it agree")
        if wanted is True and self.paired == "all":
            wanted = "all"
        object.__setattr__(self, "paired", wanted)
        return self

    @property
    def crossed(self) -> dict[str, int | None]:
        """The control parameters crossed (``"id.param"`` → the first k draws, None for all)."""
        return {name: k for name, k in self.cross.items() if name not in ("environment", "object")}


class Spec(StrictModel):
    experiment: ExperimentSpec
    render: RenderSpec = RenderSpec()
    model: ModelSpec = ModelSpec()
    models: list[ModelSpec] = Field(default_factory=list, description="Several models on the same renders "
                                    "(instead of [model]): each is inferred, results carry a `model` column.")
    evaluator: EvaluatorSpec = EvaluatorSpec()
    objects: list[ObjectSpec] = Field(min_length=1)
    environments: list[EnvironmentSpec] = Field(min_length=1)
    controls: list[dict[str, Any]] = Field(default_factory=list)
    policy: PolicySpec = PolicySpec()
    postprocess: PostprocessSpec = PostprocessSpec()
    report: ReportSpec = ReportSpec()
    aggregate: AggregateSpec = AggregateSpec()
    stability: StabilitySpec = StabilitySpec()

    @model_validator(mode="after")
    def _model_or_models(self) -> Spec:
        if self.models and "model" in self.model_fields_set:
            raise ValueError("give either [model] or [[models]], not both")
        seen: set[str] = set()
        for i, model in enumerate(self.models):
            if model.label in seen:
                raise ValueError(f"models[{i}] is called {model.label!r} like an earlier one: give it its own "
                                 "id = \"...\"")
            seen.add(model.label)
        return self

    @property
    def all_models(self) -> list[ModelSpec]:
        """The models the experiment tests, in spec order (the first is the one views show by default)."""
        return list(self.models) or [self.model]

    @field_validator("objects", "environments")
    @classmethod
    def _unique_names(cls, items: list, info: ValidationInfo) -> list:
        seen: set[str] = set()
        for i, item in enumerate(items):
            if item.name in seen:
                raise ValueError(
                    f"duplicate {info.field_name[:-1]} name {item.name!r} at [{i}]: names must be unique"
                )
            seen.add(item.name)
        return items
