"""The rendered frame, resolved from ``[render] resolution`` (a pixel size, or "model").

"model" renders exactly what the classifier sees: a frame of the model's resize size, of which
only the centre crop is rendered (Blender's render border, cropped), so the stored image is the
model's input and inference does no resampling. The sizes come from the model's preprocessing
(the infer stage's ``ModelHandle`` resolves them: statically for built-in models, from the loaded
factory for users' models), so this module needs no model.
"""

from __future__ import annotations

from dataclasses import dataclass


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

    @classmethod
    def full(cls, size: int) -> Framing:
        """A plain square frame of ``size`` pixels, all of it rendered."""
        return cls(size, size)

    @classmethod
    def of_model(cls, resize: int, crop: int) -> Framing:
        """The model's view: a frame of its resize size whose centre crop is rendered."""
        return cls(max(resize, crop), crop, model=True)

