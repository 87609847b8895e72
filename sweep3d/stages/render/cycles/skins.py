"""Procedural animal skins and image textures on object coordinates (no UVs needed).

Each skin is a small shader graph: a texture (wave bands, noise, Voronoi cells) driven by the
object-space position, a colour ramp, and a Principled BSDF. Materials are built once per
(skin, scale, image) and swapped onto every mesh slot of the current object; its own materials
are restored when a job wants them, or when another object becomes current (a worker keeps
every object it has loaded, and a hidden one must come back as it was imported).
"""

from __future__ import annotations

from typing import Any

from sweep3d.core import UserError

# skin -> (texture node, its settings, ramp stops as (position, RGB), interpolation)
_CREAM, _BLACK = (0.92, 0.88, 0.78), (0.02, 0.02, 0.02)
RECIPES: dict[str, tuple[str, dict[str, Any], list[tuple[float, tuple[float, float, float]]], str]] = {
    "zebra": ("ShaderNodeTexWave", {"wave_type": "BANDS", "bands_direction": "Z", "Scale": 2.5,
                                    "Distortion": 6.0, "Detail": 2.0}, [(0.0, _BLACK), (0.5, (0.95, 0.95, 0.95))], "CONSTANT"),
    "tiger": ("ShaderNodeTexWave", {"wave_type": "BANDS", "bands_direction": "Z", "Scale": 3.0,
                                    "Distortion": 9.0, "Detail": 3.0}, [(0.0, _BLACK), (0.35, (0.85, 0.35, 0.04))], "CONSTANT"),
    "cow": ("ShaderNodeTexNoise", {"Scale": 1.6, "Detail": 1.0, "Roughness": 0.4},
            [(0.0, (0.95, 0.95, 0.93)), (0.52, _BLACK)], "CONSTANT"),
    "giraffe": ("ShaderNodeTexVoronoi", {"feature": "DISTANCE_TO_EDGE", "Scale": 4.0},
                [(0.0, _CREAM), (0.06, (0.55, 0.3, 0.1))], "CONSTANT"),
    "leopard": ("ShaderNodeTexVoronoi", {"feature": "F1", "Scale": 6.0, "Randomness": 0.9},
                [(0.0, (0.78, 0.52, 0.2)), (0.22, _BLACK), (0.33, (0.85, 0.62, 0.28))], "CONSTANT"),
}
_OUTPUTS = {"ShaderNodeTexWave": "Fac", "ShaderNodeTexNoise": "Fac", "ShaderNodeTexVoronoi": "Distance"}


class SkinMaterials:
    """The skin materials built so far, and which one the current object wears."""

    def __init__(self, bpy) -> None:
        self.bpy = bpy
        self.materials: dict[tuple, Any] = {}
        self.meshes: list[Any] = []
        self.radius = 1.0
        self.originals: dict[str, list[Any]] = {}
        self.current: tuple = ("original",)

    def reset(self, meshes, radius: float) -> None:
        """Another object is current: remember its own materials, and its size so patterns scale
        with the object (object coordinates are in the mesh's own units)."""
        self.meshes = list(meshes)
        self.radius = radius
        self.originals = {o.name: [slot.material for slot in o.material_slots] for o in self.meshes}
        self.current = ("original",)

    def restore(self) -> None:
        """Give the current object its own materials back."""
        self.sync("original", 1.0, None)

    def changes(self, skin: str, scale: float, image: str | None) -> bool:
        """Whether :meth:`sync` with these values would swap materials."""
        return self._key(skin, scale, image) != self.current

    def _key(self, skin: str, scale: float, image: str | None) -> tuple:
        return ("original",) if skin == "original" else (skin, scale / self.radius, image)

    def sync(self, skin: str, scale: float, image: str | None) -> None:
        key = self._key(skin, scale, image)
        if key == self.current:
            return
        for obj in self.meshes:
            if key == ("original",):
                for slot, material in zip(obj.material_slots, self.originals[obj.name]):
                    slot.material = material
                if not self.originals[obj.name]:
                    obj.data.materials.clear()
                continue
            material = self._material(key)
            if not obj.material_slots:
                obj.data.materials.append(material)
            for slot in obj.material_slots:
                slot.material = material
        self.current = key

    def _material(self, key: tuple) -> Any:
        if key not in self.materials:
            self.materials[key] = self._build(*key)
        return self.materials[key]

    def _build(self, skin: str, scale: float, image: str | None) -> Any:
        """A material for ``skin``; ``scale`` is pattern repeats per unit of object coordinates."""
        bpy = self.bpy
        material = bpy.data.materials.new(f"sweep3d_skin_{skin}")
        material.use_fake_user = True  # kept for reuse while no object wears it: not an orphan to purge
        material.use_nodes = True
        nodes, links = material.node_tree.nodes, material.node_tree.links
        bsdf = nodes["Principled BSDF"]
        bsdf.inputs["Roughness"].default_value = 0.6
        coords = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.inputs["Scale"].default_value = (scale, scale, scale)
        links.new(coords.outputs["Object"], mapping.inputs["Vector"])
        if skin == "image":
            texture = nodes.new("ShaderNodeTexImage")
            try:
                texture.image = bpy.data.images.load(image, check_existing=True)
            except RuntimeError as exc:
                raise UserError(f"Blender cannot read the texture {image!r}: {exc}") from None
            texture.projection = "BOX"
            texture.projection_blend = 0.2
            links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
            links.new(texture.outputs["Color"], bsdf.inputs["Base Color"])
            return material
        node_type, settings, stops, interpolation = RECIPES[skin]
        texture = nodes.new(node_type)
        for name, value in settings.items():
            if name in texture.inputs:
                texture.inputs[name].default_value = value
            else:
                setattr(texture, name, value)
        ramp = nodes.new("ShaderNodeValToRGB")
        ramp.color_ramp.interpolation = interpolation
        elements = ramp.color_ramp.elements
        while len(elements) < len(stops):
            elements.new(0.5)
        for element, (position, rgb) in zip(elements, stops):
            element.position = position
            element.color = (*rgb, 1.0)
        links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
        links.new(texture.outputs[_OUTPUTS[node_type]], ramp.inputs["Fac"])
        links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
        return material
