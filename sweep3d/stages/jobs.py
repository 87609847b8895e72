"""Jobs and plans: what the plan stage produces and every later stage reads.

This module imports no stage, so every stage can import it without a cycle.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import pyarrow as pa

from sweep3d.spec.columns import PARAMETERS_METADATA, parameter_column
from sweep3d.spec.framing import Framing
from sweep3d.spec.loader import LoadedSpec
from sweep3d.spec.space import Point


@dataclass(frozen=True)
class Job:
    """One configuration of one scene, with the cache key of each stage it passes through.

    ``image_key`` equals ``render_key`` when no post control changes the image; ``parts_key`` is
    set only when the report asks for part visibility (a UV pass).
    """

    index: int
    object: str
    environment: str
    values: dict[str, dict[str, Any]]  # control id -> parameter -> value, for controls that apply
    render_key: str
    image_key: str
    pred_key: str
    point: Point | None = None  # where the policy put it (for policies that learn from results)
    parts_key: str | None = None  # the UV pass's visible parts, when the report asks for them

    @property
    def scene(self) -> tuple[str, str]:
        return (self.object, self.environment)


@dataclass
class Plan:
    """A spec expanded into jobs, sorted by scene.

    Attributes:
        model_digest: the model's part of every prediction key.
        out_of_frame: jobs whose object is wholly outside the frame: flagged, never rendered.
        framing: the resolved frame (``resolution = "model"`` becomes the model's sizes).
    """

    spec: LoadedSpec
    jobs: list[Job]
    model_digest: str
    out_of_frame: list[Job] = field(default_factory=list)
    framing: Framing | None = None

    @property
    def columns(self) -> list[str]:
        """One column per control parameter, in spec order."""
        return self.spec.parameter_columns

    def rows(self) -> list[dict[str, Any]]:
        """The jobs table: one row per job with its scene, control values, keys and ``in_frame``."""
        out = []
        flagged = {id(j) for j in self.out_of_frame}
        for job in sorted(self.jobs + self.out_of_frame, key=lambda j: j.index):
            row: dict[str, Any] = {"experiment": self.spec.name, "job": job.index,
                                   "object": job.object, "environment": job.environment}
            for column in self.columns:
                row[column] = None
            for control_id, values in job.values.items():
                for param, value in values.items():
                    row[parameter_column(control_id, param)] = value
            row.update(render_key=job.render_key, image_key=job.image_key, pred_key=job.pred_key,
                       parts_key=job.parts_key, in_frame=id(job) not in flagged)
            out.append(row)
        return out

    def table(self) -> pa.Table:
        """:meth:`rows` as a table whose metadata lists the parameter columns (see spec.columns)."""
        table = pa.Table.from_pylist(self.rows())
        return table.replace_schema_metadata({PARAMETERS_METADATA: json.dumps(self.columns).encode()})
