"""Per-job material edits (the ``material`` control's surface values) on working copies.

A job may set Principled BSDF inputs on all of the shown object's materials or on one by name.
The values go onto a working copy of each material (made once per material and set of edited
inputs, reused while the object stays shown), swapped into its slot for the job; the slot gets
its own material back before the next job, so the imported materials are never changed and a
texture that drove an edited input comes back with them.
"""

from __future__ import annotations

from typing import Any

from sweep3d.core import UserError
from sweep3d.stages.render.cycles.blender_looks import INPUTS, FileNames, set_inputs

#: The inputs a job may edit: the look overrides' and the emission strength.
EDITABLE = {**INPUTS, "emission": "Emission Strength"}

#: One job's edits: (target material name, "" for all; sorted (input, value) pairs), in order.
Edits = tuple[tuple[str, tuple[tuple[str, Any], ...]], ...]


class MaterialEdits:
    """The working copies of the shown object's materials, and which slots hold them now."""

    def __init__(self, bpy) -> None:
        self.bpy = bpy
        self.copies: dict[tuple[str, frozenset[str]], Any] = {}
        self.swapped: list[tuple[Any, int, Any]] = []  # (object, slot index, its own material)
        self.current: Edits = ()

    def sync(self, meshes: list[Any], names: FileNames, edits: Edits, where: str) -> None:
        """Show ``edits`` on ``meshes`` (the shown object's), undoing the previous job's first.

        Raises:
            UserError: a target names no material of the object.
        """
        if edits == self.current:
            return
        self.restore()
        if not edits:
            return
        targets = {target for target, _ in edits if target}
        present = {names.of(slot.material) for obj in meshes for slot in obj.material_slots if slot.material}
        missing = sorted(targets - present)
        if missing:
            raise UserError(f"the material control's target {missing[0]!r} is no material of {where} "
                            f"(its materials: {', '.join(sorted(present)) or 'none'})")
        for obj in meshes:
            for index, slot in enumerate(obj.material_slots):
                own = slot.material
                if own is None:
                    continue
                values: dict[str, Any] = {}
                for target, pairs in edits:
                    if target in ("", names.of(own)):
                        values.update(pairs)
                if values:
                    slot.material = self._copy(own, values)
                    self.swapped.append((obj, index, own))
        self.current = edits

    def restore(self) -> None:
        """Give every slot its own material back."""
        for obj, index, own in reversed(self.swapped):
            obj.material_slots[index].material = own
        self.swapped.clear()
        self.current = ()

    def forget(self) -> None:
        """Restore, and remove the working copies (another object is shown, or the scene is cleared)."""
        self.restore()
        for copy in self.copies.values():
            self.bpy.data.materials.remove(copy)
        self.copies.clear()

    def _copy(self, own: Any, values: dict[str, Any]) -> Any:
        key = (own.name, frozenset(values))
        copy = self.copies.get(key)
        if copy is None:  # a fresh copy per set of inputs: the links cut for them stay cut
            copy = self.copies[key] = own.copy()
            copy.use_fake_user = False
        bsdfs = [n for n in copy.node_tree.nodes if n.type == "BSDF_PRINCIPLED"] if copy.use_nodes else []
        for bsdf in bsdfs:
            set_inputs(copy.node_tree, bsdf, values, EDITABLE)
        return copy
