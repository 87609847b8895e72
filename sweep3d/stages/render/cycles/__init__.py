"""The Cycles engine (``[render] engine = "cycles"``, the default): Blender as a Python module.

Every module here works on Blender's data (``bpy``), imported only inside a render worker or a
child process (:mod:`._bpy`): the parent process that plans and drives a run never imports bpy.
"""
