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

    def protocol(self, view: tuple[int, int] | None) -> str:
        """What the model sees, in one line, for the run's output and the report: the model's own
        input rendered as it is, or a full frame the model resizes and crops itself (``view``: the
        model's resize and crop, when known).

        The object is as large in the model's input either way; a full frame of another size is
        resampled first, and a post control in pixels (blur σ) is scaled with it.
        """
        if self.model:
            return (f'resolution = "model": renders are the model\'s input, the centre {self.crop}² of a '
                    f"{self.size}² view, never resampled")
        if view is None:
            return (f"resolution = {self.size}: {self.size}² renders, which the model's own preprocessing "
                    "resizes and crops")
        resize, crop = view
        scale = resize / self.size
        if scale == 1:
            return f"resolution = {self.size}: {self.size}² renders, which the model centre-crops to {crop}² unresized"
        how = f"{'upsampled' if scale > 1 else 'downsampled'} {scale:.3g}×"
        return (f"resolution = {self.size}: {self.size}² renders, which the model resizes to {resize}² ({how}) "
                f"and centre-crops to {crop}²")

    @classmethod
    def full(cls, size: int) -> Framing:
        """A plain square frame of ``size`` pixels, all of it rendered."""
        return cls(size, size)

    @classmethod
    def of_model(cls, resize: int, crop: int) -> Framing:
        """The model's view: a frame of its resize size whose centre crop is rendered."""
        return cls(max(resize, crop), crop, model=True)

