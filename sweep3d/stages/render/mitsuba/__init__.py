"""The Mitsuba 3 engine (``[render] engine = "mitsuba"``): a second renderer for the same scenes.

It renders the plain-Python :class:`~sweep3d.stages.render.state.SceneState` the controls set,
as Cycles' workers do, in the same worker processes; :mod:`.backend` is what the rest of sweep3d
knows of it (its key, what it refuses at plan, its scene: :class:`~..backend.Backend`):

- :mod:`.objfile` reads an OBJ and its MTL as Blender's importer would (axes, smoothing,
  Principled BSDF values);
- :mod:`.translate` turns a job (object, environment, state) into Mitsuba's scene description;
- :mod:`.scene` renders it (denoised with OpenImageDenoise like Cycles), writes the same PNG
  blobs, and :mod:`.passes` the same mask and depth passes and truth numbers;
- :mod:`.kept` keeps a worker's loaded scene and sets only what a job changes, and :mod:`.frozen`
  replays its render under ``llvm_ad_rgb`` instead of tracing it again.

The ``mitsuba`` package itself is imported only by :mod:`.scene`, in a worker whose engine is
Mitsuba: nothing else in sweep3d loads it.
"""
