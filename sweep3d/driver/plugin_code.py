"""A spec's own plug-ins (``module:Name``) and the identity of their code.

Each identity is part of the keys of the stage its plug-in feeds (``core.registry.code_identity``):
rendered controls the render keys, post controls the image keys, evaluators and model factories
the prediction keys. A run records them with the experiment's jobs, so that ``plan`` can say which
plug-in changed since and how much work the change redoes. Policies are left out: their points
become the jobs' values, which the keys hold already.
"""

from __future__ import annotations

import hashlib
import json
import uuid
from dataclasses import asdict, dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from sweep3d.cache import Store
from sweep3d.core import UserError, code_identity, is_user_plugin
from sweep3d.driver.jobs import Plan
from sweep3d.spec import LoadedSpec

#: The jobs table's schema metadata key holding :func:`user_plugins` as JSON.
PLUGINS_METADATA = b"sweep3d.plugins"
#: The jobs table's schema metadata key holding :func:`spec_identity` of the spec that planned it.
SPEC_METADATA = b"sweep3d.spec"
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
    assert spec.catalogue is not None, "a spec from the loader carries its catalogue"
    evaluators, models = spec.catalogue.evaluators, spec.catalogue.models
    out: dict[str, PluginCode] = {}
    for inst in spec.controls:
        name = inst.control.type_name
        if is_user_plugin(name):
            stage = "render" if inst.control.stage == "render" else "postprocess"
            ids = out[name].ids if name in out else ()
            out[name] = PluginCode(name, stage, code_identity(type(inst.control)), (*ids, inst.id))
    if is_user_plugin(spec.evaluator.kind):
        out[spec.evaluator.kind] = PluginCode(spec.evaluator.kind, "infer", code_identity(evaluators.get(spec.evaluator.kind)))
    for model in spec.models:
        if is_user_plugin(model.name):
            out[model.name] = PluginCode(model.name, "infer", code_identity(models.get(model.name)))
    return out


def metadata(spec: LoadedSpec) -> bytes:
    """:func:`user_plugins` as the jobs table records them."""
    return json.dumps({name: asdict(p) for name, p in user_plugins(spec).items()}, sort_keys=True).encode()


def spec_identity(spec: LoadedSpec) -> str:
    """A digest of what ``spec`` was loaded from: its text as loaded (its included files' with it)
    and its user plug-ins' code, its policy's too. A run records it with the experiment's jobs, so
    that a reader can tell whether they are this spec's without planning it again (see
    :mod:`sweep3d.results.own_jobs`)."""
    h = hashlib.sha256(spec.text().encode())
    for part in (metadata(spec), _policy_code(spec).encode()):
        h.update(b"\0" + part)
    return h.hexdigest()


def recorded_identity(jobs: Path) -> str | None:
    """The :func:`spec_identity` the jobs file at ``jobs`` records (None: no readable file, or one
    written before runs recorded it, or by hand)."""
    try:
        recorded = (pq.read_schema(jobs).metadata or {}).get(SPEC_METADATA)
    except (OSError, ValueError, pa.ArrowException):
        return None
    return recorded.decode() if recorded is not None else None


def _policy_code(spec: LoadedSpec) -> str:
    """A user policy's code identity ("" for a built-in one). One whose source cannot be read gets
    an identity of its own, so that nothing is ever taken for its results without planning it."""
    if not is_user_plugin(spec.spec.policy.type):
        return ""
    try:
        return code_identity(type(spec.policy))
    except UserError:
        return f"unknown:{uuid.uuid4().hex}"


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


def plugin_changes(plan: Plan, store: Store) -> list[str]:
    """One line per changed plug-in: ``"mycontrols:Liquid changed since the last run: 120 to render"``."""
    return [f"{p.name} changed since the last run: {redone(plan, store, p)} to {VERBS[p.stage]}"
            for p in changed_since_last_run(plan.spec, store)]
