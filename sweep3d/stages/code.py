"""A spec's own plug-ins (``module:Name``) and the identity of their code.

Each identity is part of the keys of the stage its plug-in feeds (``registry.code_identity``):
rendered controls the render keys, post controls the image keys, evaluators and model factories
the prediction keys. A run records them with the experiment's jobs, so that ``plan`` can say which
plug-in changed since and how much work the change redoes. Policies are left out: their points
become the jobs' values, which the keys hold already.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass

import pyarrow.parquet as pq

from sweep3d.cache.store import Store
from sweep3d.registry import code_identity, is_user_plugin
from sweep3d.spec.loader import LoadedSpec
from sweep3d.stages.jobs import Plan

#: The jobs table's schema metadata key holding :func:`user_plugins` as JSON.
PLUGINS_METADATA = b"sweep3d.plugins"
VERBS = {"render": "render", "postprocess": "postprocess", "infer": "infer"}


@dataclass(frozen=True)
class PluginCode:
    """One user plug-in of a spec: which stage it feeds, its code's identity, and (for a control)
    the ids it has in the spec."""

    name: str
    stage: str
    code: str
    ids: tuple[str, ...] = ()


def user_plugins(spec: LoadedSpec) -> dict[str, PluginCode]:
    """The spec's user plug-ins by name."""
    from sweep3d.stages.infer import EVALUATORS, MODELS

    out: dict[str, PluginCode] = {}
    for inst in spec.controls:
        name = inst.control.type_name
        if is_user_plugin(name):
            stage = "render" if inst.control.stage == "render" else "postprocess"
            ids = out[name].ids if name in out else ()
            out[name] = PluginCode(name, stage, code_identity(type(inst.control)), (*ids, inst.id))
    if is_user_plugin(spec.evaluator.kind):
        out[spec.evaluator.kind] = PluginCode(spec.evaluator.kind, "infer", code_identity(EVALUATORS.get(spec.evaluator.kind)))
    for model in spec.models:
        if is_user_plugin(model.name):
            out[model.name] = PluginCode(model.name, "infer", code_identity(MODELS.get(model.name)))
    return out


def metadata(spec: LoadedSpec) -> bytes:
    """:func:`user_plugins` as the jobs table records them."""
    return json.dumps({name: asdict(p) for name, p in user_plugins(spec).items()}, sort_keys=True).encode()


def changed_since_last_run(spec: LoadedSpec, store: Store) -> list[PluginCode]:
    """The user plug-ins whose code differs from what the experiment's last run recorded."""
    path = store.jobs_path(spec.name)
    try:
        recorded = json.loads((pq.read_schema(path).metadata or {}).get(PLUGINS_METADATA, b"{}"))
    except (OSError, ValueError):
        return []
    return [p for name, p in user_plugins(spec).items() if name in recorded and recorded[name]["code"] != p.code]


def redone(plan: Plan, store: Store, plugin: PluginCode) -> int:
    """How many of ``plugin``'s stage's keys the plan lacks among the jobs it feeds."""
    if plugin.stage == "infer":
        keys, table = {j.pred_key for j in plan.jobs}, "predictions"
    else:
        fed = [j for j in plan.jobs if any(i in j.values for i in plugin.ids)]
        keys, table = ({j.render_key for j in fed}, "renders") if plugin.stage == "render" \
            else ({j.image_key for j in fed if j.image_key != j.render_key}, "images")  # else no post control acts
    return len(keys - store.keys(table))


def explain(plan: Plan, store: Store) -> list[str]:
    """One line per changed plug-in: ``"mycontrols:Liquid changed since the last run: 120 to render"``."""
    return [f"{p.name} changed since the last run: {redone(plan, store, p)} to {VERBS[p.stage]}"
            for p in changed_since_last_run(plan.spec, store)]
