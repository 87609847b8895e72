"""The site's reference pages, generated from the code at every ``mkdocs build`` (a mkdocs hook).

Nothing here is hand-copied: the controls, post controls, policies, evaluators and models come from
the registries the spec loader resolves names in, their parameters (type, default, range) from each
plug-in's pydantic ``Params``; the spec's tables from the pydantic spec models; the command line
from the click command tree typer builds. Text from the code is escaped, so a description holding
``<`` or ``|`` reads as written.

``SWEEP3D_DOCS_PLUGINS`` (comma-separated ``module:Name``) adds plug-ins of your own to the pages,
as a spec names them, so a team documents its controls beside the built-in ones::

    SWEEP3D_DOCS_PLUGINS=mycontrols:Vignette mkdocs build

Every internal import of the docs is in :func:`sources`: when modules move, only it changes.
"""

from __future__ import annotations

import html
import inspect
import os
import re
import types
import typing
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

#: Plug-ins of your own to document beside the built-in ones: ``module:Name``, comma-separated.
PLUGINS_ENV = "SWEEP3D_DOCS_PLUGINS"

PAGES = {
    "reference/controls.md": "controls",
    "reference/policies.md": "policies",
    "reference/evaluators.md": "evaluators",
    "reference/models.md": "models",
    "reference/spec.md": "spec",
    "reference/cli.md": "cli",
}


@dataclass
class Sources:
    """What the reference reads: the registries (name → plug-in), the spec's root model, the CLI."""

    rendered: dict[str, Any]
    post: dict[str, Any]
    policies: dict[str, Any]
    evaluators: dict[str, Any]
    models: dict[str, Any]
    spec: type
    cli: Any  # the click command tree
    model_input: Callable[[str], Any]  # a built-in model's preprocessing, or None
    extra: set[str] = field(default_factory=set)  # names that came from PLUGINS_ENV


def sources() -> Sources:
    """The registries, spec models and CLI, through the package's entry points (the one place
    the docs import sweep3d's internals), plus the plug-ins :data:`PLUGINS_ENV` names."""
    import typer

    from sweep3d.cli import app
    from sweep3d.plugins import Evaluator, Policy, PostControl, RenderedControl
    from sweep3d.runner import builtin_catalogue
    from sweep3d.spec import Spec
    from sweep3d.stages.infer import builtin_model

    plugins = builtin_catalogue()
    found = Sources(
        rendered={n: plugins.controls.get(n) for n in plugins.controls.names()
                  if plugins.controls.get(n).stage == "render"},
        post={n: plugins.controls.get(n) for n in plugins.controls.names() if plugins.controls.get(n).stage == "post"},
        policies={n: plugins.policies.get(n) for n in plugins.policies.names()},
        evaluators={n: plugins.evaluators.get(n) for n in plugins.evaluators.names()},
        models={n: plugins.models.get(n) for n in plugins.models.names()},
        spec=Spec,
        cli=typer.main.get_command(app),
        model_input=lambda name: (builtin_model(name) or (None, None))[1],
    )
    for name in filter(None, (n.strip() for n in os.environ.get(PLUGINS_ENV, "").split(","))):
        plugin = plugins.controls.get(name)  # any registry imports a ``module:Name``
        kind = (found.rendered if _subclass(plugin, RenderedControl) else found.post if _subclass(plugin, PostControl)
                else found.policies if _subclass(plugin, Policy) else found.evaluators
                if _subclass(plugin, Evaluator) else found.models)
        kind[name] = plugin
        found.extra.add(name)
    return found


def _subclass(item: Any, base: type) -> bool:
    return isinstance(item, type) and issubclass(item, base)


# --- text -------------------------------------------------------------------------------------

_CODE = re.compile(r"(``.+?``|`[^`\n]+`)")


def text(value: Any) -> str:
    """``value`` as Markdown that shows it as written: HTML and Markdown's own characters escaped
    outside code spans (RST's ````x```` becomes ```x```), pipes escaped so a table keeps its cells."""
    out = []
    for i, part in enumerate(_CODE.split(str(value))):
        if i % 2:  # a code span: Markdown shows its content as it is
            inner = part.strip("`")
            out.append(f"`{inner}`" if "`" not in inner else html.escape(inner))
        else:
            part = html.escape(part, quote=False)
            out.append(re.sub(r"([\\*_\[\]#|!])", r"\\\1", part))
    return "".join(out)


def cell(value: Any) -> str:
    """:func:`text` on one line, for a table cell."""
    return text(" ".join(str(value).split())) or " "


def doc(obj: Any) -> str:
    """An object's docstring as escaped paragraphs (a ``functools.partial``: its function's)."""
    target = getattr(obj, "func", obj)
    raw = inspect.getdoc(target) or ""
    paragraphs = [" ".join(p.split()) for p in re.split(r"\n\s*\n", raw) if p.strip()]
    return "\n\n".join(text(p) for p in paragraphs)


def type_name(annotation: Any) -> str:
    """A field's type as a reader writes it in TOML (``number``, ``"a" | "b"``, ``list of text``)."""
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is typing.Annotated:
        return type_name(args[0])
    if origin is typing.Literal:
        return " \\| ".join(f"`{value!r}`" if not isinstance(value, str) else f'`"{value}"`' for value in args)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(type_name(a) for a in args if a is not type(None)) + (
            " (optional)" if type(None) in args else "")
    if origin in (list, tuple, set, frozenset):
        inner = [a for a in args if a is not Ellipsis]
        if origin is tuple and len(inner) > 1 and len(set(inner)) == 1:
            return f"{len(inner)} × {type_name(inner[0])}"
        return "list of " + (" or ".join(type_name(a) for a in dict.fromkeys(inner)) or "values")
    if origin is dict:
        return "table"
    names = {bool: "boolean", int: "integer", float: "number", str: "text"}
    if annotation in names:
        return names[annotation]
    if isinstance(annotation, type):
        return "table" if hasattr(annotation, "model_fields") else annotation.__name__
    return cell(annotation)


def bounds(info: Any) -> str:
    """The range a pydantic field accepts, from its constraints (``0 ≤ x ≤ 1``, ``> 0``, a pattern)."""
    low = high = None
    notes = []
    for item in info.metadata:
        for name, sign in (("ge", "≥"), ("gt", ">")):
            if getattr(item, name, None) is not None:
                low = f"{_number(getattr(item, name))} {'≤' if sign == '≥' else '<'}"
        for name, sign in (("le", "≤"), ("lt", "<")):
            if getattr(item, name, None) is not None:
                high = f"{sign} {_number(getattr(item, name))}"
        if getattr(item, "pattern", None):
            notes.append(f"matches `{item.pattern}`")
        if getattr(item, "min_length", None):
            notes.append(f"at least {item.min_length}")
    if low or high:
        notes.insert(0, " ".join(filter(None, [low, "x", high])))
    return "; ".join(notes)


def _number(value: Any) -> str:
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        value = int(value)
    return f"{value:,}".replace(",", " ") if isinstance(value, int) and abs(value) >= 10_000 else str(value)


def default(info: Any) -> str:
    """A field's default as TOML would write it; ``required`` when it has none."""
    from pydantic_core import PydanticUndefined

    if info.default_factory is not None:
        value = info.default_factory()
    elif info.default is PydanticUndefined:
        return "required"
    else:
        value = info.default
    if hasattr(value, "model_fields"):
        return "(its table's defaults)"
    if value is None:
        return "none"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, str):
        return f'`"{value}"`' if "`" not in value else cell(repr(value))
    if isinstance(value, (int, float)):
        return f"`{_number(value)}`"
    return cell(value)


def fields_table(model: Any, skip: Iterable[str] = ()) -> str:
    """One row per field of a pydantic model: name, type, default, range, description."""
    shown = {name: info for name, info in model.model_fields.items() if name not in skip}
    if not shown:
        return "No parameters."
    described = any(info.description for info in shown.values())  # a column only where some field has one
    rows = ["| key | type | default | range |" + (" description |" if described else ""),
            "|---|---|---|---|" + ("---|" if described else "")]
    for name, info in shown.items():
        rows.append(f"| `{name}` | {type_name(info.annotation)} | {default(info)} | {cell(bounds(info))} |"
                    + (f" {cell(info.description or '')} |" if described else ""))
    return "\n".join(rows)


def _anchor(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def _own(name: str, found: Sources) -> str:
    return f" (from `{PLUGINS_ENV}`)" if name in found.extra else ""


# --- pages ------------------------------------------------------------------------------------


def controls(found: Sources) -> str:
    out = ["# Controls", "",
           "Every control a spec may name under `[[controls]] type = ...`, generated from the registries "
           "at build time. A parameter takes a value, a list or a range (`{ range = [low, high] }`); its default "
           "is neutral: a job at the defaults is keyed and rendered as if the control were absent. A parameter "
           "becomes the column `<id>_<param>` of `jobs` and `results` (the id defaults to the type). How to use "
           "them: [Controls](../how-to/controls.md).", ""]
    for title, kind, what in (("Rendered controls", found.rendered, "change the 3D scene before Blender renders it"),
                              ("Post controls", found.post, "map the rendered image to another: changing one "
                               "re-renders nothing")):
        out += [f"## {title}", "", f"These {what}.", ""]
        for name in sorted(kind):
            control = kind[name]
            out += [f"### `{name}`{_own(name, found)}", "", doc(control), ""]
            notes = []
            if getattr(control, "periodic", None):
                notes.append("wraps: " + ", ".join(f"`{p}` every {_number(v)}" for p, v in control.periodic.items()))
            if getattr(control, "passes", ()):
                notes.append("reads the " + " and ".join(f"`{p}`" for p in control.passes) + " pass")
            if notes:
                out += ["*" + "; ".join(notes) + ".*", ""]
            out += [fields_table(control.Params), ""]
    return "\n".join(out)


def policies(found: Sources) -> str:
    out = ["# Policies", "",
           "Every search policy a spec may name under `[policy] type = ...`; the table's other keys are the "
           "policy's parameters below (`paired` and `cross` belong to the planner: see "
           "[the spec's `[policy]`](spec.md#policy)). How to choose: [Policies](../how-to/policies.md).", ""]
    for name in sorted(found.policies):
        policy = found.policies[name]
        out += [f"## `{name}`{_own(name, found)}", "", doc(policy), "", fields_table(policy.Params), ""]
    return "\n".join(out)


def evaluators(found: Sources) -> str:
    out = ["# Evaluators", "",
           "Every evaluator a spec may name under `[evaluator] kind = ...`: what the model must return (`task`), "
           "the render passes it reads, the columns it adds to `results` and its settings (other keys of "
           "`[evaluator]`). How to use them: [Tasks](../how-to/tasks.md).", ""]
    for name in sorted(found.evaluators):
        evaluator = found.evaluators[name]
        passes = ", ".join(f"`{p}`" for p in evaluator.passes) or "none"
        columns = ", ".join(f"`{f.name}` ({cell(str(f.type))})" for f in evaluator.schema)
        out += [f"## `{name}`{_own(name, found)}", "", doc(evaluator), "",
                f"- **task** (what the model returns): `{evaluator.task}`", f"- **passes**: {passes}",
                f"- **columns**: {columns}", "", fields_table(evaluator.Params), ""]
    return "\n".join(out)


def models(found: Sources) -> str:
    out = ["# Models", "",
           "Every built-in model a spec may name under `[model] name = ...` (or `[[models]]`); a model of your "
           "own is a factory named `module:factory` ([Your own model](../how-to/own-model.md)).", "",
           "| name | input (resize → centre crop) | description |", "|---|---|---|"]
    for name in sorted(found.models):
        preprocess = found.model_input(name)
        size = (f"{preprocess.resize} → {preprocess.crop}²" if preprocess is not None else "its factory's")
        description = doc(found.models[name]).replace("\n\n", " ")
        variant = getattr(found.models[name], "args", ())
        if variant and "``variant``" in (inspect.getdoc(getattr(found.models[name], "func", None)) or ""):
            description = description.replace("`variant`", str(variant[0]))
        out.append(f"| `{name}`{_own(name, found)} | {size} | {description} |")
    return "\n".join(out) + "\n"


def spec(found: Sources) -> str:
    root = found.spec
    out = ["# The spec", "",
           "Every table and key of a spec file, generated from the pydantic models the loader validates "
           "against. A key not listed here is refused with one line naming it. A worked example: "
           "[Write a spec](../how-to/spec.md).", ""]
    notes = {
        "controls": "Each `[[controls]]` table has `type` (a name from [Controls](controls.md), or "
                    "`module:Name`), an optional `id` (default: the type), optional `objects = [...]` and "
                    "`environments = [...]` that limit it to those scenes, and its parameters.",
        "policy": "The policy's own parameters go in this table too: see [Policies](policies.md).",
        "evaluator": "The evaluator's own settings go in this table too: see [Evaluators](evaluators.md).",
    }
    for name, info in root.model_fields.items():
        model, many = _model_of(info.annotation)
        header = f"[[{name}]]" if many else f"[{name}]"
        out += [f"## `{header}` {{#{_anchor(name)}}}", ""]
        if info.description:
            out += [text(info.description), ""]
        if name in notes:
            out += [notes[name], ""]
        if model is None:
            continue
        if model.__doc__ and model.__doc__ is not getattr(model.__mro__[1], "__doc__", None):
            out += [doc(model), ""]
        out += [fields_table(model), ""]
        for sub, sub_info in model.model_fields.items():
            nested, sub_many = _model_of(sub_info.annotation)
            if nested is not None:
                out += [f"### `{name}.{sub}`", "", doc(nested), "", fields_table(nested), ""]
    return "\n".join(out)


def _model_of(annotation: Any) -> tuple[Any, bool]:
    """The pydantic model a field holds (itself, a list of it, a dict of it, or optional), and whether many."""
    args = typing.get_args(annotation)
    origin = typing.get_origin(annotation)
    if hasattr(annotation, "model_fields"):
        return annotation, False
    if origin is list and args and hasattr(args[0], "model_fields"):
        return args[0], True
    if origin is dict and len(args) == 2 and hasattr(args[1], "model_fields"):
        return args[1], True
    if origin in (typing.Union, types.UnionType):
        for arg in args:
            model, many = _model_of(arg)
            if model is not None:
                return model, many
    return None, False


def cli(found: Sources) -> str:
    out = ["# Command line", "",
           "Every command and option of `sweep3d`, generated from its click command tree. "
           "`sweep3d COMMAND --help` prints the same.", ""]
    root = found.cli
    out += _command(root, "sweep3d", level=2, top=True)
    return "\n".join(out)


def _command(command: Any, path: str, level: int, top: bool = False) -> list[str]:
    """A command's help and parameters, then its subcommands'. Duck-typed: typer carries its own
    copy of click's classes, so ``isinstance`` against ``click``'s would find nothing."""
    out = []
    if not top:
        out += [f"{'#' * level} `{path}`", ""]
    if command.help:
        out += [doc(types.SimpleNamespace(__doc__=command.help)), ""]
    params = [p for p in command.params if p.name != "help"]
    if params:
        out += ["| argument or option | type | default | description |", "|---|---|---|---|"]
        for param in params:
            names = ", ".join(f"`{o}`" for o in [*param.opts, *param.secondary_opts])
            if param.param_type_name == "argument":
                names = f"`{(param.metavar or param.name).upper()}`" + (" (required)" if param.required else "")
            kind = "flag" if getattr(param, "is_flag", False) else _param_type(param)
            value = param.default
            shown = "" if value is None or callable(value) or value == () else f"`{value}`"
            out.append(f"| {names} | {kind} | {shown} | {cell(getattr(param, 'help', None) or '')} |")
        out.append("")
    if hasattr(command, "list_commands"):
        context = command.context_class(command)
        for name in command.list_commands(context):
            sub = command.get_command(context, name)
            if sub is not None and not sub.hidden:
                out += _command(sub, f"{path} {name}", level if top else level + 1)
    return out


def _param_type(param: Any) -> str:
    """A CLI parameter's type, with its range (typer's own parameters describe their annotation;
    click's name their type)."""
    annotation = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    if annotation is not None:
        kind = type_name(annotation).replace("PosixPath", "path").replace("Path", "path")
    else:
        kind = cell(getattr(getattr(param, "type", None), "name", "") or "text")
    low, high = getattr(param, "min", None), getattr(param, "max", None)
    if low is not None or high is not None:
        kind += " (" + " ".join(filter(None, [f"{low} ≤" if low is not None else "", "x",
                                              f"≤ {high}" if high is not None else ""])) + ")"
    return kind


def generate() -> dict[str, str]:
    """Every generated page: path under ``docs/`` → Markdown."""
    found = sources()
    makers = {"controls": controls, "policies": policies, "evaluators": evaluators, "models": models,
              "spec": spec, "cli": cli}
    return {path: makers[what](found) for path, what in PAGES.items()}


# --- the mkdocs hook --------------------------------------------------------------------------


def on_files(files: Any, config: Any) -> Any:
    """Add the generated pages to the site (mkdocs calls this before it builds the navigation)."""
    from mkdocs.structure.files import File

    for path, content in generate().items():
        existing = files.get_file_from_path(path)
        if existing is not None:
            files.remove(existing)
        files.append(File.generated(config, path, content=content))
    return files


if __name__ == "__main__":  # print the pages: python scripts/docs_reference.py
    for path, content in generate().items():
        print(f"<!-- {path} -->\n{content}")
