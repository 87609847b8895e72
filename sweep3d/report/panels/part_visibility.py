"""Part visibility (the paper's Figure 8): accuracy conditioned on each part of an object being seen.

Shown only when the spec asks for it (``[report] part_visibility = true``, which makes the
renderer write a UV pass). Per object: the object rendered from six sides with each part of its
surface painted the colour of the accuracy over the images that show that part (grey: shown in
too few images to say), and the same numbers as a map of azimuth × elevation around the object.
The coloured renders are made once per object and colouring, and kept in the store.
"""

from __future__ import annotations

import base64
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from sweep3d.assets import materialise_mesh, mesh_digest
from sweep3d.cache import Store, atomic_write, digest
from sweep3d.core import AZIMUTH_PARTS, ELEVATION_PARTS, PARTS, PARTS_LAYOUT, part_bounds
from sweep3d.report.figures import ACCURACY_COLORSCALE, Figure, accuracy_rgb, layout, make_figure, pct
from sweep3d.report.panel import PanelInputs
from sweep3d.results import has_view
from sweep3d.stages.render import SIDES, Look, paint_objects

UNSEEN = (0.93, 0.93, 0.93)  # never shown in an image
TOO_FEW = (0.72, 0.72, 0.72)  # shown, but in fewer images than the panel's minimum
PAINT_VERSION = 1  # bump when the coloured renders change for the same colours
LISTED = 3  # parts named as the worst and best seen
_SEP = "<br>"  # between lines of a hover text


def build(inputs: PanelInputs) -> dict[str, Any] | None:
    """One block per object: coloured renders, an azimuth × elevation map, the worst and best parts."""
    if not has_view(inputs.con, "part_visibility"):
        return None
    rows = inputs.rows("SELECT * FROM part_visibility")
    if not rows:
        return None
    by_object: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        by_object[row["object"]].append(row)
    minimum = inputs.min_count
    blocks = []
    for index, (name, parts) in enumerate(sorted(by_object.items(), key=lambda kv: kv[1][0]["object_accuracy"])):
        reliable = sorted((p for p in parts if p["n"] >= minimum), key=lambda p: (p["accuracy"], -p["n"]))
        blocks.append({
            "object": name, "images": parts[0]["object_n"], "accuracy": pct(parts[0]["object_accuracy"]),
            "colours": _colours(parts, minimum), "figure": _figure(index, name, parts, minimum),
            "worst": [_describe(p) for p in reliable[:LISTED] if p["lift"] < 0],
            "best": [_describe(p) for p in reversed(reliable[-LISTED:]) if p["lift"] > 0],
        })
    _attach_renders(inputs, blocks)
    return {"objects": blocks, "minimum": minimum}


def _colours(parts: list[dict[str, Any]], minimum: int) -> np.ndarray:
    colours = np.tile(np.asarray(UNSEEN, dtype=np.float32), (PARTS, 1))
    for p in parts:
        colours[p["part"]] = accuracy_rgb(p["accuracy"]) if p["n"] >= minimum else TOO_FEW
    return colours


def _attach_renders(inputs: PanelInputs, blocks: list[dict[str, Any]]) -> None:
    """Give each block its coloured renders (``sides``: label and data URI), painting what the
    store does not hold yet in one Blender process."""

    store, loaded = inputs.store, inputs.loaded
    todo: list[tuple[str, np.ndarray, list[Path], Look | None]] = []
    objects = {o.name: o for o in loaded.objects}
    for block in blocks:
        ref, colours = loaded.meshes[block["object"]], block.pop("colours")
        value = {"paint": PAINT_VERSION, "layout": PARTS_LAYOUT, "mesh": mesh_digest(ref, store.root),
                 "colours": np.round(colours, 3).tolist(), "views": SIDES}  # "views": as keyed before
        look = objects[block["object"]].look_key()
        if look:
            value["look"] = look  # only parts show; without a look the key is as before
        paths = [_paint_path(store, digest(value), label) for label, _, _ in SIDES]
        if not all(p.exists() for p in paths):
            todo.append((ref, colours, paths, Look.of(objects[block["object"]])))
        block["sides"] = list(zip([label for label, _, _ in SIDES], paths))
    if todo:
        painted = paint_objects([(str(materialise_mesh(ref, store.root)), colours) for ref, colours, _, _ in todo],
                                looks=[look for *_, look in todo])
        for (_, _, paths, _), images in zip(todo, painted):
            for path, png in zip(paths, images):
                atomic_write(path, png)
    for block in blocks:
        block["sides"] = [{"label": label, "uri": _data_uri(path)} for label, path in block["sides"]]


def _paint_path(store: Store, key: str, view: str) -> Path:
    return store.root / "cache" / "paint" / key[:2] / f"{key}-{view}.png"


def _data_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _describe(part: dict[str, Any]) -> dict[str, Any]:
    return {"where": _where(part["part"]), "accuracy": pct(part["accuracy"], 0), "count": part["n"],
            "lift": f"{part['lift'] * 100:+.0f} pts"}


def _where(part: int) -> str:
    a0, a1, e0, e1 = part_bounds(part)
    return f"azimuth {a0:g}° to {a1:g}°, elevation {e0:g}° to {e1:g}°"


def _figure(index: int, name: str, parts: list[dict[str, Any]], minimum: int) -> Figure:
    """Accuracy per part on an azimuth × elevation map (front at 0°, the object's right at +90°)."""
    z: list[list[float | None]] = [[None] * AZIMUTH_PARTS for _ in range(ELEVATION_PARTS)]
    hover = [[f"never shown{_SEP}{_where(b * AZIMUTH_PARTS + s)}" for s in range(AZIMUTH_PARTS)]
             for b in range(ELEVATION_PARTS)]
    too_few: list[list[float | None]] = [[None] * AZIMUTH_PARTS for _ in range(ELEVATION_PARTS)]
    for p in parts:
        band, slice_ = divmod(p["part"], AZIMUTH_PARTS)
        if p["n"] >= minimum:
            z[band][slice_] = p["accuracy"]
        else:
            too_few[band][slice_] = 1.0
        hover[band][slice_] = (f"accuracy {pct(p['accuracy'])} when shown ({p['n']} images; 95 % CI "
                               f"{pct(p['wilson_low'], 0)}–{pct(p['wilson_high'], 0)})<br>object overall "
                               f"{pct(p['object_accuracy'])}: {p['lift'] * 100:+.0f} pts{_SEP}{_where(p['part'])}")
    width, height = 360 / AZIMUTH_PARTS, 180 / ELEVATION_PARTS
    cells = {"x": [-180 + (s + 0.5) * width for s in range(AZIMUTH_PARTS)],
             "y": [-90 + (b + 0.5) * height for b in range(ELEVATION_PARTS)], "xgap": 1, "ygap": 1,
             "hovertext": hover, "hovertemplate": "%{hovertext}<extra></extra>"}
    grey = "rgb({0},{0},{0})".format(round(TOO_FEW[0] * 255))
    traces = [
        {"type": "heatmap", "z": too_few, "zmin": 0, "zmax": 1, "colorscale": [[0, grey], [1, grey]],
         "showscale": False, **cells},
        {"type": "heatmap", "z": z, "zmin": 0, "zmax": 1, "colorscale": ACCURACY_COLORSCALE, "hoverongaps": True,
         "colorbar": {"tickformat": ".0%", "title": {"text": "accuracy"}}, **cells},
    ]
    figure_layout = layout(
        height=300, margin={"l": 56, "r": 16, "t": 16, "b": 48}, plot_bgcolor="#eeeeee",
        xaxis={"title": {"text": "azimuth around the object (° from its front; +90 = its right)"},
               "tickvals": [-180, -90, 0, 90, 180], "range": [-180, 180], "zeroline": False},
        showlegend=False, yaxis={"title": {"text": "elevation (°)"}, "tickvals": [-90, -45, 0, 45, 90], "range": [-90, 90],
               "zeroline": False},
    )
    query = f"FROM part_visibility WHERE object = '{name.replace(chr(39), chr(39) * 2)}'"
    return make_figure(f"fig-parts-{index}", traces, figure_layout, query)

