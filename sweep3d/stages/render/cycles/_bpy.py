"""The one place that imports bpy, with install hints instead of a bare ImportError."""

from __future__ import annotations

from sweep3d.core import UserError


def import_bpy():
    """Import and return the bpy module (call inside render workers only)."""
    import sys

    if "bpy" not in sys.modules:
        # A process spawned by one that imported bpy inherits bpy's own script folders on
        # sys.path, where a pure-Python "bpy" shadows the real module: drop them first.
        sys.path[:] = [p for p in sys.path if "/bpy/" not in p.replace("\\", "/") + "/"
                       or p.rstrip("/").endswith("site-packages")]
    try:
        import bpy  # noqa: PLC0415
    except ImportError as exc:
        hint = (
            "install Blender as a module: pip install 'bpy==4.5.15' (Python 3.11, numpy<2)"
            if "No module named" in str(exc)
            else "on Debian install: apt-get install libx11-6 libxrender1 libxfixes3 libxi6 "
            "libxkbcommon0 libsm6 libice6 libxext6 libgl1"
        )
        raise UserError(f"cannot import bpy ({exc}); {hint}") from None
    return bpy
