"""The Blender world: an HDRI (rotatable, scalable), a plain colour's neutral light, or a sky.

The world node tree is rebuilt only when its structure changes (another map, a sky) and its
values are written only when they differ, because any change makes Cycles rebuild the world's
importance map (~0.75 s at 224² on 2 cores).
"""

from __future__ import annotations

import math
from typing import Any

from sweep3d.errors import UserError
from sweep3d.stages.render._rna import assign
from sweep3d.stages.render.state import SceneState


class WorldView:
    def __init__(self, bpy, world) -> None:
        self.bpy, self.world = bpy, world
        self.structure: tuple | None = None
        self.nodes: dict[str, Any] = {}

    def sync(self, env: dict[str, Any], state: SceneState) -> None:
        """Make the world show ``env`` (or the state's sky) with the state's rotation and strength."""
        sky = state.sky
        structure = ("sky",) if sky is not None else ("hdri", env["hdri"]) if env.get("hdri") else ("plain",)
        if structure != self.structure:
            self._build(structure, env)
            self.structure = structure
        strength = env["strength"] * state.world_strength
        if sky is not None:
            strength = sky.strength * state.world_strength
            node = self.nodes["sky"]
            assign(node, "sun_elevation", math.radians(sky.sun_elevation))
            assign(node, "sun_rotation", math.radians(sky.sun_azimuth))
        if "mapping" in self.nodes:
            assign(self.nodes["mapping"].inputs["Rotation"], "default_value", (0.0, 0.0, math.radians(state.world_rotation)))
        assign(self.nodes["background"].inputs["Strength"], "default_value", strength)

    def _build(self, structure: tuple, env: dict[str, Any]) -> None:
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
                texture.image = self.bpy.data.images.load(env["hdri"], check_existing=True)
            except RuntimeError as exc:
                raise UserError(f"Blender cannot read the HDRI {env['hdri']!r}: {exc}") from None
            if texture.image.size[0] == 0:  # Blender loads unreadable images silently (a magenta world)
                raise UserError(f"Blender cannot read the HDRI {env['hdri']!r}; save it again as .exr or .hdr")
            links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
            links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
            links.new(texture.outputs["Color"], background.inputs["Color"])
            self.nodes["mapping"] = mapping
        elif structure[0] == "sky":
            sky = nodes.new("ShaderNodeTexSky")
            sky.sky_type = "NISHITA"
            sky.sun_disc = True
            links.new(sky.outputs["Color"], background.inputs["Color"])
            self.nodes["sky"] = sky
        else:
            # A plain background is composited after rendering; the world only lights the object.
            background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
