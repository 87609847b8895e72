"""The Blender world: an HDRI (rotatable, scalable), a plain colour's neutral light (dimmed to its
key light's fill), or a sky.

A render worker keeps one :class:`WorldNodes` (one bpy World) per environment. Its node tree is
rebuilt only when its structure changes (a sky instead of the map) and its values are written
only when they differ, because any change makes Cycles rebuild the world's importance map
(~0.75 s at 224² on 2 cores).
"""

from __future__ import annotations

import math
from typing import Any

from sweep3d.core import UserError
from sweep3d.stages.render.cycles._rna import assign
from sweep3d.stages.render.state import SceneState
from sweep3d.stages.render.worker_protocol import EnvironmentRef

GROUND_ALBEDO = 0.3  # below the horizon of a procedural sky


class WorldNodes:
    """One bpy World and the nodes :meth:`sync` writes to."""

    def __init__(self, bpy, world) -> None:
        self.bpy, self.world = bpy, world
        self.structure: tuple | None = None
        self.nodes: dict[str, Any] = {}
        self._pixels: tuple[str, int] | None = None  # (image name, pixels) of the map last measured

    def sync(self, env: EnvironmentRef, state: SceneState) -> None:
        """Make the world show ``env`` (or the state's sky) with the state's rotation and strength."""
        sky = state.sky
        structure = ("sky",) if sky is not None else ("hdri", env.hdri) if env.hdri else ("plain",)
        if structure != self.structure:
            self._build(structure, env)
            self.structure = structure
        strength = env.strength * state.world_strength
        if env.key_light is not None and sky is None:
            strength *= env.key_light.fill  # the key light takes the rest (scene.py adds it)
        if sky is not None:
            strength = sky.strength * state.world_strength
            node = self.nodes["sky"]
            assign(node, "sun_elevation", math.radians(sky.sun_elevation))
            assign(node, "sun_rotation", math.radians(sky.sun_azimuth))
            colour = next(i for i in self.nodes["ground"].inputs if i.identifier == "B_Color")
            assign(colour, "default_value", ground_colour(sky.sun_elevation))
        if "mapping" in self.nodes:
            assign(self.nodes["mapping"].inputs["Rotation"], "default_value", (0.0, 0.0, math.radians(state.world_rotation)))
        assign(self.nodes["background"].inputs["Strength"], "default_value", strength)

    def _build(self, structure: tuple, env: EnvironmentRef) -> None:
        self.world.use_nodes = True
        tree = self.world.node_tree
        nodes, links = tree.nodes, tree.links
        nodes.clear()
        out = nodes.new("ShaderNodeOutputWorld")
        background = nodes.new("ShaderNodeBackground")
        links.new(background.outputs["Background"], out.inputs["Surface"])
        self.nodes = {"background": background}
        if structure[0] == "hdri":
            coords = nodes.new("ShaderNodeTexCoord")
            mapping = nodes.new("ShaderNodeMapping")
            texture = nodes.new("ShaderNodeTexEnvironment")
            try:
                texture.image = self.bpy.data.images.load(env.hdri, check_existing=True)
            except RuntimeError as exc:
                raise UserError(f"Blender cannot read the HDRI {env.hdri!r}: {exc}") from None
            if texture.image.size[0] == 0:  # Blender loads unreadable images silently (a magenta world)
                raise UserError(f"Blender cannot read the HDRI {env.hdri!r}; save it again as .exr or .hdr")
            links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
            links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
            links.new(texture.outputs["Color"], background.inputs["Color"])
            self.nodes["mapping"], self.nodes["texture"] = mapping, texture
        elif structure[0] == "sky":
            sky = nodes.new("ShaderNodeTexSky")
            sky.sky_type = "NISHITA"
            sky.sun_disc = True
            self.nodes["ground"] = self._ground(nodes, links, sky, background)
            self.nodes["sky"] = sky
        else:
            # A plain background is composited after rendering; the world only lights the object.
            background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)

    @property
    def pixels(self) -> int:
        """Pixels of the HDRI this world holds in memory (0 for a plain colour or a sky).

        Read once per map: ``image.size`` asks Blender for the image buffer, and the kept worlds'
        budget is summed after every job (it was 18 % of a worker's Python time)."""
        texture = self.nodes.get("texture")
        if texture is None:
            return 0
        if self._pixels is None or self._pixels[0] != texture.image.name:
            self._pixels = (texture.image.name, int(texture.image.size[0]) * int(texture.image.size[1]))
        return self._pixels[1]

    @staticmethod
    def _ground(nodes, links, sky, background) -> Any:
        """Nishita's sky is black below the horizon (and takes no direction input to mirror it):
        show a plain ground there, its brightness set from the sun in :meth:`sync`."""
        coords = nodes.new("ShaderNodeTexCoord")
        split = nodes.new("ShaderNodeSeparateXYZ")
        below = nodes.new("ShaderNodeMath")
        below.operation = "LESS_THAN"
        below.inputs[1].default_value = 0.0
        ground = nodes.new("ShaderNodeMix")
        ground.data_type = "RGBA"
        links.new(coords.outputs["Generated"], split.inputs["Vector"])
        links.new(split.outputs["Z"], below.inputs[0])
        links.new(below.outputs["Value"], ground.inputs["Factor"])
        links.new(sky.outputs["Color"], ground.inputs["A"])
        links.new(ground.outputs["Result"], background.inputs["Color"])
        return ground


def ground_colour(sun_elevation: float) -> tuple[float, float, float, float]:
    """Linear RGBA of a grey ground lit by a sun at ``sun_elevation`` degrees (a little sky light
    when the sun is down): albedo × (direct + ambient), in the sky's units at strength 1."""
    lit = GROUND_ALBEDO * (max(math.sin(math.radians(sun_elevation)), 0.0) + 0.05)
    return (lit, lit, lit, 1.0)
