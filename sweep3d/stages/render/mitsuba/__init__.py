"""The Mitsuba 3 engine (``[render] engine = "mitsuba"``): a second renderer for the same scenes.

It renders the plain-Python :class:`~sweep3d.stages.render.state.SceneState` the controls set,
as Cycles' workers do, in the same worker processes (:func:`~..worker.make_scene`):

- :mod:`.objfile` reads an OBJ and its MTL as Blender's importer would (axes, smoothing,
  Principled BSDF values);
- :mod:`.translate` turns a job (object, environment, state) into Mitsuba's scene description;
- :mod:`.scene` renders it (denoised with OpenImageDenoise like Cycles), writes the same PNG
  blobs, and :mod:`.passes` the same mask and depth passes and truth numbers.

Imported only when the engine is Mitsuba: nothing else in sweep3d loads ``mitsuba``.
"""
