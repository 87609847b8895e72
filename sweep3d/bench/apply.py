"""Write a chosen setting into a spec's [render] table, keeping its comments and layout."""

from __future__ import annotations

from pathlib import Path

import tomlkit

from sweep3d.bench.measurement import Setting


def apply_setting(spec_path: Path, setting: Setting, spec_resolution: int | str) -> None:
    """The seed is the reference's business, never written; adaptive sampling only when on or named."""
    doc = tomlkit.parse(spec_path.read_text(encoding="utf-8"))
    render = doc.get("render")
    if render is None:
        render = tomlkit.table()
        doc["render"] = render
    for key, value in setting.render_update(spec_resolution).items():
        if key == "seed" or (key == "adaptive_threshold" and not value and key not in render):
            continue
        render[key] = value
    spec_path.write_text(tomlkit.dumps(doc), encoding="utf-8")
