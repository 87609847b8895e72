"""Load a TOML spec into a validated, path-resolved :class:`LoadedSpec`.

Every mistake becomes a :class:`~sweep3d.core.errors.SpecError` naming the file, the key path and
what is expected, so the CLI can print one line instead of a traceback.
"""

from __future__ import annotations

import difflib
import importlib
import logging
import sys
import tomllib
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from sweep3d.assets import (
    check_archive,
    check_file,
    check_hdri,
    check_materials,
    check_mesh,
    not_a_file,
    resolve_hdri,
    resolve_mesh,
)
from sweep3d.cache import store_folder_problem
from sweep3d.core import Control, SpecError, UserError, declaration_problem, is_spec_path, is_user_plugin
from sweep3d.spec.catalogue import Catalogue
from sweep3d.spec.class_names import NameClash, spec_class_names
from sweep3d.spec.columns import (
    JOB_COLUMNS,
    MODEL_NAME_COLUMNS,
    PREDICTION_COLUMNS,
    TRUTH_RESULT_COLUMNS,
    parameter_column,
)
from sweep3d.spec.includes import BASE_KEY, located, merge_includes
from sweep3d.spec.looks import check_look, valid_keys
from sweep3d.spec.models import (
    EnvironmentSpec,
    EvaluatorSpec,
    ExperimentSpec,
    ModelSpec,
    ObjectSpec,
    PostprocessSpec,
    RenderSpec,
    ReportSpec,
    Spec,
)
from sweep3d.spec.params import Choice, Fixed, ParamSyntaxError, Range, Space, parse_space

RESERVED_CONTROL_KEYS = {"type", "id", "objects", "environments"}
log = logging.getLogger("sweep3d.spec")


@dataclass(frozen=True)
class ControlInstance:
    """A control as configured in the spec: its plug-in, its parameter spaces and where it applies."""

    control: Control
    spaces: dict[str, Space]
    objects: frozenset[str] | None = None
    environments: frozenset[str] | None = None

    @property
    def id(self) -> str:
        return self.control.id

    @property
    def columns(self) -> list[str]:
        """This control's parameter columns in the jobs and results tables."""
        return [parameter_column(self.id, param) for param in self.spaces]

    def applies_to(self, object_name: str, environment_name: str) -> bool:
        return (self.objects is None or object_name in self.objects) and (
            self.environments is None or environment_name in self.environments
        )


@dataclass(frozen=True)
class LoadedSpec:
    """A validated spec with its file, resolved paths, controls and policy."""

    path: Path
    spec: Spec
    store: Path
    meshes: dict[str, str]  # object name -> resolved mesh reference
    hdris: dict[str, str | None]  # environment name -> resolved HDRI path (None for colours)
    labels: dict[str, tuple]  # object name -> ImageNet ids (built-in models) or the labels as given
    controls: list[ControlInstance] = field(default_factory=list)
    policy: Any = None
    source: str | None = None  # the spec's text as loaded (a dict's as TOML), its included files' after it
    #: the registries its names resolved in: what the driver looks evaluators and models up in
    #: (without importing the stages that declare them)
    catalogue: Catalogue | None = field(default=None, compare=False, repr=False)

    def text(self) -> str:
        """The spec as written when it was loaded (what the runs table records)."""
        return self.source if self.source is not None else self.path.read_text(encoding="utf-8")

    @property
    def name(self) -> str:
        return self.spec.experiment.name

    # The spec's tables, so callers write ``loaded.render`` rather than ``loaded.spec.render``.
    @property
    def experiment(self) -> ExperimentSpec:
        return self.spec.experiment

    @property
    def render(self) -> RenderSpec:
        return self.spec.render

    @property
    def postprocess(self) -> PostprocessSpec:
        return self.spec.postprocess

    @property
    def model(self) -> ModelSpec:
        """The first model (the one the views and report show unless asked for another)."""
        return self.spec.all_models[0]

    @property
    def models(self) -> list[ModelSpec]:
        """Every model the experiment tests, in spec order."""
        return self.spec.all_models

    @property
    def evaluator(self) -> EvaluatorSpec:
        return self.spec.evaluator

    @property
    def objects(self) -> list[ObjectSpec]:
        return self.spec.objects

    @property
    def environments(self) -> list[EnvironmentSpec]:
        return self.spec.environments

    @property
    def report(self) -> ReportSpec:
        return self.spec.report

    @property
    def parameter_columns(self) -> list[str]:
        """Every control parameter's column, in spec order."""
        return [column for inst in self.controls for column in inst.columns]

    def fail(self, key: str, problem: str) -> SpecError:
        return SpecError(str(self.path), key, problem)


def spec_from_file(path: str | Path, catalogue: Catalogue) -> LoadedSpec:
    """Read, validate and resolve a spec file (``sweep3d.load`` is the public way in).

    Args:
        catalogue: the controls, policies, models and evaluators its names may refer to
            (``sweep3d.stages.builtin_catalogue()`` for the built-in ones).

    Raises:
        SpecError: for any mistake in the file, naming the key and the fix.
    """
    path = Path(path)
    text = _read_text(path)  # kept: what was loaded is what text() says, whatever the file says later
    return validate_spec(parse_toml(text, str(path)), catalogue, path=path, base=path.resolve().parent, source=text)


def validate_spec(raw: dict[str, Any], catalogue: Catalogue, *, path: Path, base: Path,
                  source: str | None = None) -> LoadedSpec:
    """Validate and resolve a spec already read into a dict (from a file, a string or a notebook).

    Args:
        path: what errors name as the file (``<dict>`` or ``<string>`` for a spec with none).
        base: the folder relative meshes, HDRIs, files and the store resolve against.
        source: the spec's text, for one that has no file to read it back from.

    Raises:
        SpecError: for any mistake, naming ``path`` (or the included file), the key and the fix.
    """
    included = merge_includes(raw, str(path), base)
    if included.texts:  # the runs table records what the spec was made of
        own = source if source is not None else path.read_text(encoding="utf-8")
        source = own + "".join(f"\n\n# ---- included: {file} ----\n{text}" for file, text in included.texts)
    try:
        return _validated(included.raw, catalogue, path=path, base=base, source=source, folders=included.folders)
    except SpecError as exc:
        raise located(exc, included) from None


def _validated(raw: dict[str, Any], catalogue: Catalogue, *, path: Path, base: Path, source: str | None,
               folders: list[Path]) -> LoadedSpec:
    try:
        spec = Spec.model_validate(raw)
    except ValidationError as exc:
        raise _first_error(path, exc) from None
    fail = lambda key, problem: SpecError(str(path), key, problem)  # noqa: E731
    _check_engine(spec, fail, catalogue)

    meshes = {}
    for i, obj in enumerate(spec.objects):
        try:
            meshes[obj.name] = resolve_mesh(obj.mesh, base)
            check_archive(meshes[obj.name], spec.experiment.max_archive_mb)
            check_mesh(meshes[obj.name])
            materials = check_materials(meshes[obj.name])
        except UserError as exc:
            raise fail(f"objects[{i}].mesh", _naming(obj.mesh, exc)) from None
        for warning in materials.warnings:
            log.warning(f"warning: {path}: objects[{i}].mesh: {_naming(obj.mesh, warning)}")
        check_look(obj, meshes[obj.name], i, fail)
    hdris: dict[str, str | None] = {}
    for i, env in enumerate(spec.environments):
        try:
            hdris[env.name] = resolve_hdri(env.hdri, base) if env.hdri is not None else None
            # the built-in maps are known to be good (and DWA-compressed, which radiance does not read)
            warning = check_hdri(hdris[env.name], pixels=not env.hdri.startswith("builtin:")) if env.hdri is not None else None
        except UserError as exc:
            raise fail(f"environments[{i}].hdri", _naming(env.hdri or "", exc)) from None
        if warning:
            log.warning(f"warning: {path}: environments[{i}].hdri: {_naming(env.hdri or '', warning)}")

    if _names_user_plugins(spec):
        for folder in reversed([base, *folders]):  # the spec's folder first on the path, then the included files'
            plugin_folder(folder)
    _check_model(spec, fail, catalogue)
    evaluator = _load_evaluator(spec, fail, catalogue)
    labels = _resolve_labels(spec, fail, catalogue)
    controls = _load_controls(spec, fail, base, catalogue)
    _check_columns(controls, fail, evaluator)
    policy = _load_policy(spec, fail, catalogue, controls, base)
    store = Path(spec.experiment.store)
    store = (store if store.is_absolute() else base / store).resolve()
    problem = store_folder_problem(store)
    if problem:
        raise fail("experiment.store", problem)
    return LoadedSpec(path, spec, store, meshes, hdris, labels, controls, policy, source, catalogue)


def plugin_folder(folder: Path) -> None:
    """Make the modules in a spec's folder importable (first on ``sys.path``), so ``module:Name``
    finds a plug-in file beside the spec whatever the working directory; render workers started
    afterwards inherit the path (each is sent the parent's ``sys.path``: ``stages.render.child``)."""
    entry = str(folder)
    if entry not in sys.path:
        sys.path.insert(0, entry)


def _names_user_plugins(spec: Spec) -> bool:
    names = [spec.policy.type, spec.evaluator.kind, *(m.name for m in spec.all_models)]
    names += [c.get("type") for c in spec.controls if isinstance(c.get("type"), str)]
    return any(is_user_plugin(name) for name in names)


def _naming(ref: str, problem: UserError | str) -> str:
    """The problem's message, prefixed with the file as the spec gives it unless it already says it."""
    message = str(problem)
    name = Path(ref.partition("#")[2] or ref).name
    return message if not ref or (name and name in message) else f"{ref}: {message}"


def _read_text(path: Path) -> str:
    kind = not_a_file(path)
    if kind is not None and kind != "a directory":  # a FIFO's read would wait for a writer for ever
        raise SpecError(str(path), "", f"is {kind}, not a spec file; give the path of a TOML file")
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SpecError(str(path), "", "no such spec file; check the path") from None
    except PermissionError as exc:
        raise SpecError(str(path), "", f"cannot read the spec ({exc.strerror}); fix its permissions") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(str(path), "", f"cannot read the spec: {exc}") from None


def parse_toml(text: str, file: str) -> dict[str, Any]:
    """The TOML ``text`` as a dict; a syntax error, or values nested deeper than
    :data:`MAX_NESTING`, is a :class:`SpecError` naming ``file``.

    tomllib parses arrays and inline tables by recursion: a few kilobytes of ``[[[[…`` exceed
    Python's recursion limit, and values nested less deeply still crash whatever walks them later.
    """
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(file, "", f"not valid TOML: {exc}") from None
    except RecursionError:
        raise SpecError(file, "", f"values nested too deeply to read (arrays or inline tables inside one "
                                  f"another); a spec nests them at most {MAX_NESTING} levels: flatten them") from None
    deep = too_deep(raw)
    if deep is not None:
        raise SpecError(file, deep, f"values nested more than {MAX_NESTING} levels deep (arrays or tables inside one "
                                    "another); a spec needs a few levels: flatten it")
    return raw


#: How deeply a spec's values may nest (arrays and tables inside one another); a spec needs about 5.
MAX_NESTING = 32


def too_deep(raw: dict[str, Any], limit: int = MAX_NESTING) -> str | None:
    """The key path (its first levels, then ``…``) of a value of ``raw`` nested more than ``limit``
    levels deep, or None. Walked with a stack of its own, never by recursion (what it guards against)."""
    stack: list[tuple[Any, str, int]] = [(raw, "", 0)]
    while stack:
        value, where, depth = stack.pop()
        if depth > limit:
            return where
        if isinstance(value, dict):
            stack.extend((v, _deeper(where, f".{k}" if where else str(k), depth), depth + 1) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((v, _deeper(where, f"[{i}]", depth), depth + 1) for i, v in enumerate(value))
    return None


def _deeper(where: str, step: str, depth: int, shown: int = 4) -> str:
    """``where`` one level deeper: its first ``shown`` levels named, the rest one ``…``."""
    if depth < shown:
        return where + step
    return where if where.endswith("…") else where + "…"


def _first_error(path: Path, exc: ValidationError) -> SpecError:
    err = _cause(exc.errors())
    key = _key_path(err["loc"])
    msg = err["msg"]
    if err["type"] == "extra_forbidden":
        msg = "unknown key; remove it or check its spelling"
        valid = valid_keys(Spec, err["loc"][:-1])
        close = difflib.get_close_matches(str(err["loc"][-1]), valid, n=1) if valid else []
        if close:
            msg = f"unknown key; remove it or check its spelling (did you mean {close[0]!r}? valid: {', '.join(valid)})"
    elif err["type"] == "missing":
        msg = "required key is missing"
    elif "input" in err and err["type"] not in ("value_error",):
        msg = f"{msg} (got {err['input']!r})"
    more = len(exc.errors()) - 1
    if more:
        msg += f" (and {more} more error{'s' if more > 1 else ''})"
    return SpecError(str(path), key, msg.removeprefix("Value error, "))


def _cause(errors: list[Any]) -> Any:
    """The error to report: the first, unless it is a missing key whose misspelling is an unknown
    key of the same table (``enviroments`` for ``environments``), which names the actual mistake."""
    first = errors[0]
    if first["type"] != "missing":
        return first
    parent, name = first["loc"][:-1], str(first["loc"][-1])
    for err in errors:
        loc = err["loc"]
        if err["type"] == "extra_forbidden" and loc[:-1] == parent and difflib.get_close_matches(str(loc[-1]), [name]):
            return err
    return first


def _key_path(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


def _check_engine(spec: Spec, fail, catalogue: Catalogue) -> None:
    """``[render] engine`` must name a registered engine (what it can render is the planner's check)."""
    engine = spec.render.engine
    if engine not in catalogue.engines:
        close = difflib.get_close_matches(engine, catalogue.engines.names(), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise fail("render.engine", f"unknown engine {engine!r}{hint}; use one of {', '.join(catalogue.engines.names())}")


def _check_model(spec: Spec, fail, catalogue: Catalogue) -> None:
    where = [f"models[{i}]" for i in range(len(spec.models))] or ["model"]
    for key, model in zip(where, spec.all_models):
        _check_name(f"{key}.name", catalogue.models, model.name, fail)
    first = catalogue.labels(spec.all_models[0].name)
    for key, model in zip(where[1:], spec.all_models[1:]):
        classes = catalogue.labels(model.name)  # None: a user's model, checked once loaded
        if first is not None and classes is not None and classes != first:
            raise fail(f"{key}.name", f"{model.name!r} names other classes than {spec.all_models[0].name!r}; "
                       "models compared in one spec must share their class names (objects' labels are theirs)")


def _load_evaluator(spec: Spec, fail, catalogue: Catalogue) -> Any:
    """The evaluator class ``[evaluator] kind`` names (a user's module is imported now), its
    declaration checked and the table's other keys validated against its ``Params``."""
    kind = spec.evaluator.kind
    try:
        cls = catalogue.evaluators.get(kind)
    except UserError as exc:
        raise fail("evaluator.kind", str(exc)) from None
    problem = declaration_problem(cls)
    if problem is not None:
        raise fail("evaluator.kind", f"evaluator {kind!r} {problem}")
    fields = cls.Params.model_fields
    for name in spec.evaluator.params:
        if name not in fields:
            close = difflib.get_close_matches(name, fields, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            valid = ", ".join(["kind", "passes", "min_visible", *fields])
            raise fail(f"evaluator.{name}", f"unknown setting for evaluator {kind!r}{hint}; valid: {valid}")
    try:
        cls.Params(**spec.evaluator.params)
    except ValidationError as exc:
        err = exc.errors()[0]
        raise fail(f"evaluator.{_key_path(err['loc'])}", _params_problem(err)) from None
    return cls


def _check_name(key: str, registry: Any, name: str, fail) -> None:
    if ":" not in name:
        try:
            registry.get(name)
        except UserError as exc:
            raise fail(key, str(exc)) from None


def _resolve_labels(spec: Spec, fail, catalogue: Catalogue) -> dict[str, tuple]:
    """Check labels against a built-in model's classes (one name per class: see ``spec.class_names``);
    a user's model checks its own when it is loaded."""
    classes = catalogue.labels(spec.all_models[0].name)
    out: dict[str, tuple] = {}
    for i, obj in enumerate(spec.objects):
        if classes is None:
            out[obj.name] = tuple(obj.labels)
            continue
        ids = []
        for j, label in enumerate(obj.labels):
            try:
                ids.append(classes.index(label))
            except ValueError as exc:
                raise fail(f"objects[{i}].labels[{j}]", str(exc)) from None
        out[obj.name] = tuple(sorted(set(ids)))
    if classes is not None:
        try:
            spec_class_names([obj.labels for obj in spec.objects], classes)
        except NameClash as exc:
            raise fail(exc.key, str(exc)) from None
    return out


def _load_controls(spec: Spec, fail, base: Path, catalogue: Catalogue) -> list[ControlInstance]:
    instances: list[ControlInstance] = []
    ids: set[str] = set()
    object_names = {o.name for o in spec.objects}
    env_names = {e.name for e in spec.environments}
    for i, entry in enumerate(spec.controls):
        where = f"controls[{i}]"
        type_name = entry.get("type")
        if not isinstance(type_name, str):
            raise fail(f"{where}.type", f"required; one of: {', '.join(catalogue.controls.names())}")
        try:
            cls = catalogue.controls.get(type_name)
        except UserError as exc:
            raise fail(f"{where}.type", str(exc)) from None
        if not (isinstance(cls, type) and issubclass(cls, Control)):
            raise fail(f"{where}.type", f"{type_name!r} is not a sweep3d Control subclass")
        if getattr(cls, "stage", None) == "render" and not importable_by_name(cls):
            raise fail(f"{where}.type", _unreachable_in_workers(cls))
        control_id = entry.get("id", type_name.rsplit(":", 1)[-1])
        if not isinstance(control_id, str) or not control_id.isidentifier():
            raise fail(f"{where}.id", "must be a name made of letters, digits and underscores")
        if control_id in ids:
            raise fail(f"{where}.id", f"control id {control_id!r} is used twice; give this one its own id = '...'")
        ids.add(control_id)
        control = cls(control_id, type_name)
        folder = Path(entry[BASE_KEY]) if BASE_KEY in entry else base  # an included file's control: its folder
        spaces = _control_spaces(control, {k: v for k, v in entry.items() if k != BASE_KEY}, f"{where}", fail, folder)
        objects = _name_filter(entry, "objects", object_names, where, fail)
        environments = _name_filter(entry, "environments", env_names, where, fail)
        instances.append(ControlInstance(control, spaces, objects, environments))
    return instances


def importable_by_name(cls: type) -> bool:
    """Whether another process can import ``cls`` by its module and name, as pickle does.

    A class defined in ``__main__`` (a notebook cell, the script being run) is not: a render
    worker never runs the user's script (see ``stages.render.child``), so it could not find it.
    """
    if cls.__module__ in ("__main__", "__mp_main__") or "<locals>" in cls.__qualname__:
        return False
    try:
        found: Any = importlib.import_module(cls.__module__)
        for part in cls.__qualname__.split("."):
            found = getattr(found, part)
    except Exception:  # noqa: BLE001  (any failure means a worker could not find it either)
        return False
    return found is cls


def _unreachable_in_workers(cls: type) -> str:
    where = "a function" if "<locals>" in cls.__qualname__ else (
        "__main__ (a notebook cell or the script being run)" if cls.__module__ in ("__main__", "__mp_main__")
        else f"module {cls.__module__!r}, which does not hold it under that name")
    name = cls.__qualname__.rsplit(".", 1)[-1]
    return (f"rendered control {name} is defined in {where}; render workers are separate processes that import "
            f"it by name: put the class in a module file beside the spec (e.g. mycontrols.py) and name it as "
            f"type = \"mycontrols:{name}\" (post controls may stay: they run in this process)")


def _check_columns(controls: list[ControlInstance], fail, evaluator: Any) -> None:
    """Refuse a parameter whose column would collide with another column of ``jobs`` or ``results``
    (``render`` + ``key`` would shadow ``render_key``; ``a`` + ``b_c`` and ``a_b`` + ``c`` would merge)."""
    reserved = (set(JOB_COLUMNS) | set(PREDICTION_COLUMNS) | set(TRUTH_RESULT_COLUMNS) | set(evaluator.schema.names)
                | set(evaluator.roles.aliases()) | set(MODEL_NAME_COLUMNS.values()))
    seen: dict[str, str] = {}
    for i, inst in enumerate(controls):
        for param in inst.spaces:
            column = parameter_column(inst.id, param)
            where = f"controls[{i}].{param}"
            if column in reserved:
                raise fail(where, f"its column {column!r} is one of the results table's own columns; "
                                  f"give the control another id = '...'")
            if column in seen:
                raise fail(where, f"its column {column!r} is also {seen[column]}'s; give the control another id = '...'")
            seen[column] = f"controls[{i}] {inst.id}.{param}"


def _control_spaces(control: Control, entry: dict[str, Any], where: str, fail, base: Path) -> dict[str, Space]:
    fields = control.Params.model_fields
    spaces: dict[str, Space] = {}
    for name, raw in entry.items():
        if name in RESERVED_CONTROL_KEYS:
            continue
        if name not in fields:
            close = difflib.get_close_matches(name, fields, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise fail(
                f"{where}.{name}",
                f"unknown parameter for control {control.type_name!r}{hint}; valid: {', '.join(fields)}",
            )
        try:
            space = parse_space(raw)
        except ParamSyntaxError as exc:
            raise fail(f"{where}.{name}", str(exc)) from None
        spaces[name] = _check_space(control, name, space, f"{where}.{name}", fail)
        if is_spec_path(fields[name]):
            spaces[name] = _resolve_paths(spaces[name], base, f"{where}.{name}", fail)
    for name, (stands_for, *_) in control.folds.items():
        if name in spaces and stands_for in spaces:
            raise fail(f"{where}.{name}", f"{name!r} sets the {stands_for!r} of control {control.type_name!r}: "
                                          f"give {stands_for} or {name}, not both")
    return spaces


def _resolve_paths(space: Space, base: Path, key: str, fail) -> Space:
    """A file parameter's values as absolute paths (relative ones against the spec's folder)."""

    def resolve(value: str) -> str:
        if not value:
            return value
        path = Path(value).expanduser()
        path = path if path.is_absolute() else base / path
        try:
            check_file(path, "file", "paths are relative to the spec file")
        except UserError as exc:
            raise fail(key, _naming(value, exc)) from None
        return str(path.resolve())

    if isinstance(space, Choice):
        return Choice(tuple(resolve(v) for v in space.options))
    return Fixed(resolve(space.value))


def _check_space(control: Control, name: str, space: Space, key: str, fail) -> Space:
    """Validate every value a space can produce against the control's parameter model."""

    def check(value: Any) -> Any:
        try:
            return getattr(control.Params(**{name: value}), name)
        except ValidationError as exc:
            raise fail(key, _params_problem({**exc.errors()[0], "input": value})) from None

    if isinstance(space, Fixed):
        return Fixed(check(space.value))
    if isinstance(space, Choice):
        return Choice(tuple(check(v) for v in space.options))
    annotation = numeric(control.Params.model_fields[name].annotation)
    if annotation not in (int, float):
        raise fail(key, f"a range needs a numeric parameter; {name!r} takes {getattr(annotation, '__name__', annotation)}: use a list")
    check(space.low)
    check(space.high)
    return Range(space.low, space.high, log=space.log, integer=annotation is int)


def numeric(annotation: Any) -> Any:
    """``int`` or ``float`` for a parameter that takes one (also when it may be None: "keep as is")."""
    args = [a for a in typing.get_args(annotation) if a is not type(None)]
    return args[0] if len(args) == 1 and len(typing.get_args(annotation)) == 2 else annotation


def _name_filter(entry, key, valid: set[str], where: str, fail) -> frozenset[str] | None:
    if key not in entry:
        return None
    names = entry[key]
    if not (isinstance(names, list) and all(isinstance(n, str) for n in names) and names):
        raise fail(f"{where}.{key}", f"must be a non-empty list of {key[:-1]} names")
    unknown = [n for n in names if n not in valid]
    if unknown:
        raise fail(f"{where}.{key}", f"unknown {key[:-1]} {unknown[0]!r}; valid: {', '.join(sorted(valid))}")
    return frozenset(names)


def _load_policy(spec: Spec, fail, catalogue: Catalogue, controls: list[ControlInstance], base: Path):
    params = {k: v for k, v in (spec.policy.model_extra or {}).items()}
    try:
        cls = catalogue.policies.get(spec.policy.type)
    except UserError as exc:
        raise fail("policy.type", str(exc)) from None
    _check_policy_class(cls, spec.policy.type, fail)
    if spec.policy.paired and getattr(cls, "adaptive", False):
        key = "cross" if {"environment", "object"} & set(spec.policy.cross) else "paired"
        raise fail(f"policy.{key}", f"the {spec.policy.type} policy learns per scene, so its points cannot be "
                                    f"shared across scenes; use random or sobol, or remove {key}")
    if spec.policy.crossed and getattr(cls, "adaptive", False):
        raise fail("policy.cross", f"the {spec.policy.type} policy learns per scene from the points it drew; "
                                   "cross lists with random, sobol or grid")
    for name in spec.policy.crossed:
        _check_crossed(name, controls, fail)
    try:
        policy = cls(cls.Params(**params))
    except ValidationError as exc:
        err = exc.errors()[0]
        raise fail(f"policy.{_key_path(err['loc'])}", _params_problem(err)) from None
    if getattr(policy, "lists_jobs", False) and (spec.policy.cross or spec.policy.paired):
        raise fail("policy.cross" if spec.policy.cross else "policy.paired",
                   f"the {spec.policy.type} policy lists every job's values itself; remove cross and paired")
    bind = getattr(policy, "bind", None)
    if bind is not None:
        try:
            bind(base, controls, [o.name for o in spec.objects], [e.name for e in spec.environments])
        except SpecError:  # names its own file (a design table's row and column)
            raise
        except UserError as exc:
            raise fail("policy", str(exc)) from None
    return policy


def _check_policy_class(cls: Any, name: str, fail) -> None:
    """Refuse a ``[policy] type`` naming something that is not a policy class (a function, another
    class), which would otherwise fail deep in planning with an AttributeError."""
    from sweep3d.stages.plan import Policy  # that module imports this one

    if not (isinstance(cls, type) and issubclass(cls, Policy)):
        what = f"a {type(cls).__name__}" if not isinstance(cls, type) else f"class {cls.__qualname__}"
        raise fail("policy.type", f"{name!r} is {what}, not a sweep3d Policy subclass; a policy "
                                  "subclasses sweep3d.plugins.Policy and returns its points from points()")


def _check_crossed(name: str, controls: list[ControlInstance], fail) -> None:
    """A crossed name is ``"<control id>.<param>"`` of a listed parameter (a range is drawn, not crossed)."""
    control_id, _, param = name.partition(".")
    space = next((inst.spaces.get(param) for inst in controls if inst.id == control_id), None)
    if space is None:
        valid = ", ".join(["environment", "object", *(f"{i.id}.{p}" for i in controls for p, s in i.spaces.items()
                                                       if isinstance(s, Choice))])
        raise fail("policy.cross", f"{name!r} names no control parameter the spec sets; give \"<control id>.<param>\" "
                                   f"of a list, \"environment\" or \"object\" (here: {valid})")
    if not isinstance(space, Choice):
        what = "a range, which the policy draws" if isinstance(space, Range) else "one value"
        raise fail("policy.cross", f"{name!r} is {what}; only a list of two or more values (e.g. skin = "
                                   "[\"zebra\", \"tiger\"]) is crossed")


def _params_problem(err: dict[str, Any]) -> str:
    """A plug-in ``Params`` model's first validation error as a line: pydantic's message with the
    value it got (a value error's own message already says it)."""
    if err["type"] == "extra_forbidden":
        return "unknown key; remove it or check its spelling"
    if err["type"] == "missing":
        return "required key is missing"
    problem = err["msg"].removeprefix("Value error, ")
    return problem if "input" not in err or err["type"] == "value_error" else f"{problem} (got {err['input']!r})"
