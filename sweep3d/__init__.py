"""sweep3d: find where vision models fail by rendering 3D scenes under systematic variation.

The package root imports neither bpy nor torch, so the CLI, the planner and the
store start fast; the render stage imports bpy only inside its worker processes.
"""

__version__ = "0.1.0"
