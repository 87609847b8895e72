"""The rendered frame, resolved from ``[render] resolution`` (a pixel size, or "model").

"model" renders exactly what the classifier sees: a frame of the model's resize size, of which
only the centre crop is rendered (Blender's render border, cropped), so the stored image is the
model's input and inference does no resampling. The sizes come from the model's preprocessing:
known statically for built-in models, read from the loaded factory for users' models.
"""

from __future__ import annotations

from dataclasses import dataclass

from sweep3d.errors import SpecError, UserError


@dataclass(frozen=True)
class Framing:
    """A square frame of ``size`` pixels whose centre ``crop`` pixels are rendered and stored.

    ``model`` is True when the frame is the model's view: its preprocessing then keeps only the
    normalisation. The crop's top-left corner is where the model's centre crop puts it.
    """

    size: int
    crop: int
    model: bool = False

    @property
    def offset(self) -> int:
        """Pixels between the frame's top (or left) edge and the crop, as ``Preprocess`` computes it."""
        return (self.size - self.crop) // 2

    def key_part(self) -> dict[str, int]:
        """What goes into render keys: a full frame hashes as before ("resolution" alone)."""
        if self.crop == self.size:
            return {"resolution": self.size}
        return {"resolution": self.size, "crop": self.crop}


def resolve_framing(spec) -> Framing:
    """The frame of a :class:`~sweep3d.spec.loader.LoadedSpec` (loads a user's model for "model").

    Raises:
        SpecError: naming ``render.resolution`` when the model's input size cannot be known.
    """
    resolution = spec.spec.render.resolution
    if resolution != "model":
        return Framing(resolution, resolution)
    from sweep3d.stages.infer.models import input_geometry

    try:
        resize, crop = input_geometry(spec.spec.model.name)
    except SpecError:
        raise
    except UserError as exc:
        raise SpecError(str(spec.path), "render.resolution", str(exc)) from None
    return Framing(max(resize, crop), crop, model=True)
