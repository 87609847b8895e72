"""The Python API, for notebooks and scripts: what the command line does, as calls.

    import sweep3d

    exp = sweep3d.load({"experiment": {"name": "mugs"}, ...}, base="assets")  # or a path, or TOML text
    exp.plan()                  # the jobs, what is cached and to compute, an estimate; nothing is rendered
    exp.run()                   # render, postprocess and infer what the store lacks
    df = exp.dataframe()        # the results (exp.results() for a pyarrow Table)
    exp.sql("SELECT * FROM control_accuracy")  # any read-only SELECT over the views (pandas=True: a DataFrame)
    exp.report("mugs.html")
    exp.explain(budget=200)     # the nearest fix of each failure (a seeded sample within the budget)

The command line is a thin layer over this module: ``run``, ``query`` and ``report`` call the same
functions, so both raise the same one-line :class:`~sweep3d.core.errors.UserError` for a user's mistake.
What they read is the spec's own results: when the experiment last ran another version of the
spec, the jobs are this one's, with a warning for those that have no result yet (see
:mod:`sweep3d.results.own_jobs`).
Importing it imports neither bpy nor torch.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Mapping, Union, overload

from sweep3d.core import UserError

if TYPE_CHECKING:
    import pandas
    import pyarrow as pa
    from rich.console import Console

    from sweep3d.export import ExportResult
    from sweep3d.followups.confirm import ConfirmResult
    from sweep3d.followups.explain import ExplainResult
    from sweep3d.followups.grade import Graded
    from sweep3d.runner import PlanStatus, RunResult
    from sweep3d.spec import LoadedSpec

#: A spec: a file's path, TOML text (a string holding a newline or starting with ``[``) or a dict.
SpecSource = Union[str, Path, Mapping[str, Any]]
EXECUTORS = ("local", "ray")
#: pyarrow's integer types → pandas' nullable integer dtypes.
NULLABLE_INTEGERS = {f"{sign}int{bits}": f"{sign.upper()}Int{bits}" for sign in ("", "u") for bits in (8, 16, 32, 64)}


def load(spec: SpecSource, *, base: str | Path | None = None) -> Experiment:
    """The experiment ``spec`` describes; see :class:`Experiment`."""
    return Experiment(spec, base=base)


class Experiment:
    """One experiment: its validated spec, and the calls that plan, run and read it.

    Args:
        spec: a spec file's path, the text of one, or a dict of its tables (arrays of tables as
            lists of dicts). In a dict a plug-in may be the class itself (``{"type": Vignette}``),
            as it would be named ``"module:Vignette"`` in a file; a rendered control must come from
            a module file (render workers import it by name), post controls, policies, models and
            evaluators may be defined in the notebook.
        base: the folder a dict's or a string's relative paths (meshes, HDRIs, the store) resolve
            against; default the working directory. A file's resolve against its own folder.

    Raises:
        SpecError: for any mistake in the spec, naming the file (``<dict>``, ``<string>``), the key
            and the fix.
    """

    def __init__(self, spec: SpecSource, *, base: str | Path | None = None) -> None:
        self.spec: LoadedSpec = _load_spec(spec, base)

    def __repr__(self) -> str:
        return f"Experiment({self.name!r}, spec={str(self.spec.path)!r}, store={str(self.store)!r})"

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def store(self) -> Path:
        """The store folder the experiment's renders and results are kept in."""
        return self.spec.store

    def plan(self) -> PlanStatus:
        """The plans of the spec's models and, per stage, the keys needed, cached and to compute with
        an estimate of the time (what ``sweep3d plan`` prints); ``.jobs`` and ``.table()`` are the
        first model's jobs (``.plans`` has every model's). Nothing is rendered."""
        from sweep3d.runner import plan_status

        return plan_status(self.spec)

    def run(self, progress: bool = True, *, wait: float = 0.0, executor: str = "local",
            address: str | None = None, console: Console | None = None) -> RunResult:
        """Render, postprocess and infer what the store lacks; resumable, like ``sweep3d run``.

        Args:
            progress: show progress bars (the returned :class:`~sweep3d.runner.pipeline.RunResult` holds the
                stages' outcomes; ``sweep3d run`` prints them).
            wait: seconds to wait for another run holding the store's lock.
            executor: where renders run, ``local`` worker processes or ``ray``.
            address: with ``ray``, the cluster's address (default: start a local one).
            console: print there (the command line's console), whatever ``progress`` says.
        """
        from rich.console import Console

        from sweep3d.runner import run as run_pipeline
        from sweep3d.stages.render import Executor

        check_wait(wait)
        if executor not in EXECUTORS:
            raise UserError(f"executor {executor!r}: use local or ray")
        console = console or (Console() if progress else None)
        return run_pipeline(self.spec, console, wait=wait, executor=Executor(executor, address))

    def explain(self, budget: int | None = None, *, seed: int | None = None, progress: bool = True,
                wait: float = 0.0, console: Console | None = None) -> ExplainResult:
        """For each failure of the finished run (a seeded sample within ``budget`` new renders), the
        nearest configuration where the model is right; like ``sweep3d explain``: resumable, its
        renders cached, the results in the ``counterfactuals`` view (:meth:`counterfactuals`)."""
        from rich.console import Console

        from sweep3d.followups.explain import explain_spec, print_explained

        check_wait(wait)
        console = console or (Console() if progress else None)
        result = explain_spec(self.spec, budget=budget, seed=seed, console=console, wait=wait)
        if console is not None:
            print_explained(console, result, self.spec.path)
        return result

    def counterfactuals(self) -> pa.Table:
        """What :meth:`explain` found: one row per failure searched (the ``counterfactuals`` view)."""
        return self.sql("SELECT * FROM counterfactuals ORDER BY failure_job")

    @overload
    def sql(self, query: str, model: str | None = None, *, pandas: Literal[False] = False) -> pa.Table: ...

    @overload
    def sql(self, query: str, model: str | None = None, *, pandas: Literal[True]) -> pandas.DataFrame: ...

    def sql(self, query: str, model: str | None = None, *, pandas: bool = False) -> pa.Table | pandas.DataFrame:
        """The rows of one read-only SELECT over the views (``results``, ``control_accuracy``, …; see
        the docs, how-to/query.md) of this spec's own jobs, as ``sweep3d query`` answers it.

        Args:
            model: the model whose results the views show (its id; default the spec's first).
            pandas: return a pandas DataFrame instead of a pyarrow Table: integer columns as
                nullable integer dtypes (``Int64``: a missing value stays ``<NA>``, not a float NaN).
        """
        from sweep3d.results import arrow, results_connection, select_only

        statement = select_only(query, "read the rows and write them with pyarrow or pandas")
        with results_connection(self.spec, model, statement=statement) as con:
            table = arrow(con, statement)
        return to_pandas(table) if pandas else table

    def results(self, model: str | None = None) -> pa.Table:
        """One row per job with its parameters, prediction and verdict, ordered by job."""
        return self.sql("SELECT * FROM results ORDER BY job", model)

    def dataframe(self, model: str | None = None) -> pandas.DataFrame:
        """:meth:`results` as a pandas DataFrame, typed for analysis: ``object`` and ``environment``
        as categoricals in spec order (plots and groupbys follow the spec, not the alphabet),
        integers as nullable dtypes (``Int64``), and without the columns of control parameters the
        spec never sets (their defaults, the same in every row; :meth:`results` keeps them)."""
        frame = to_pandas(self.results(model))
        frame = frame.drop(columns=[c for c in unset_parameters(self.spec) if c in frame and _constant(frame[c])])
        for column, names in (("object", [o.name for o in self.spec.objects]),
                              ("environment", [e.name for e in self.spec.environments])):
            if column in frame:
                frame[column] = _categorical(frame[column], names)
        return frame

    def export(self, format: str, output: str | Path | None = None, *, where: str | None = None,
               model: str | None = None, unevaluable: str = "skip", append: bool = False,
               link: bool = False) -> ExportResult:
        """Write the results ``where`` chooses (default: the failures) as a ``coco``,
        ``imagefolder`` or ``parquet`` dataset, or your own (``"module:Name"``, a
        ``sweep3d.plugins.DatasetWriter``), with ``design.csv``, as ``sweep3d export`` does."""
        from sweep3d.export import export_dataset

        return export_dataset(self.spec, format, output=Path(output) if output is not None else None, where=where,
                              model=model, unevaluable=unevaluable, append=append, link=link)

    def confirm(self, renders: int | None = None, seed: int | None = None, progress: bool = True, *,
                wait: float = 0.0) -> ConfirmResult:
        """Test each significant finding of the last run on fresh renders, like ``sweep3d confirm``
        (``renders`` per finding, default 64; ``seed`` default the spec's; ``wait``: seconds to wait
        for another command holding the store's lock); the verdicts are kept for the findings and
        the report."""
        from rich.console import Console

        from sweep3d.followups.confirm import confirm
        from sweep3d.results import DEFAULT_RENDERS

        check_wait(wait)
        return confirm(self.spec, renders or DEFAULT_RENDERS, seed, Console() if progress else None, wait=wait)

    def grade(self, budget: int | None = None, seed: int | None = None, progress: bool = True, *,
              wait: float = 0.0) -> Graded:
        """Grade every finding of the last run, like ``sweep3d grade`` (``budget``: the most renders
        the checks may use, cached ones included, default two thirds of what the run rendered; ``seed``
        default the spec's); the grades are the ``findings`` view's and lead the report."""
        from rich.console import Console

        from sweep3d.followups.grade import grade_findings

        check_wait(wait)
        return grade_findings(self.spec, budget, seed, Console() if progress else None, wait=wait)

    def report(self, path: str | Path | None = None, model: str | None = None) -> Path:
        """Write the HTML report (default ``<store>/reports/<experiment>.html``) and return its path."""
        from sweep3d.report import write_report

        return write_report(self.spec, Path(path) if path is not None else None, model)

    def compare(self) -> pa.Table:
        """The spec's models against each other on the jobs both answered: accuracy difference,
        fixed and broken jobs, McNemar's p-value and agreement (the ``model_agreement`` view)."""
        require_models(self.spec)
        return self.sql("SELECT * FROM model_agreement ORDER BY model_a, model_b")


def to_pandas(table: pa.Table) -> pandas.DataFrame:
    """``table`` as a DataFrame whose integer columns are pandas' nullable integers (pyarrow's
    default makes a column with a missing value float64, its integers floats)."""
    pandas = _pandas()
    dtypes = {arrow: pandas.api.types.pandas_dtype(name) for arrow, name in NULLABLE_INTEGERS.items()}
    return table.to_pandas(types_mapper=lambda kind: dtypes.get(str(kind)))


def _pandas() -> Any:
    try:
        import pandas
    except ImportError:
        raise UserError("results as a DataFrame need pandas: pip install pandas (or use results(), "
                        "a pyarrow Table)") from None
    return pandas


def unset_parameters(spec: LoadedSpec) -> list[str]:
    """The columns of control parameters ``spec`` does not set: the planner records their
    defaults, so that a job's row says everything that made its image."""
    from sweep3d.spec import parameter_column

    listed = set(spec.parameter_columns)
    return [column for inst in spec.controls for param in inst.control.Params.model_fields
            if (column := parameter_column(inst.id, param)) not in listed]


def _constant(column: pandas.Series) -> bool:
    return column.nunique(dropna=False) <= 1


def _categorical(column: pandas.Series, names: list[str]) -> pandas.Series:
    """``column`` as a categorical whose categories are ``names`` in that order (any other value
    the results hold after them)."""
    extra = [v for v in dict.fromkeys(column.dropna()) if v not in names]
    return column.astype(_pandas().CategoricalDtype([*names, *extra]))


def require_models(spec: LoadedSpec) -> None:
    """Refuse to compare a spec that tests one model."""
    if len(spec.models) < 2:
        raise UserError(f"{spec.path}: the spec tests one model; list two or more under [[models]] to compare them")


def check_wait(seconds: float) -> float:
    """``wait``, refused when negative or not finite (typer reads ``-5`` and ``nan`` as floats)."""
    if not (math.isfinite(seconds) and seconds >= 0):
        raise UserError(f"--wait {seconds:g}: give the seconds to wait for the store's lock, a finite number >= 0 "
                        "(0: do not wait)")
    return seconds


def _load_spec(spec: SpecSource, base: str | Path | None) -> LoadedSpec:
    """Load ``spec`` from wherever it comes, against the built-in plug-ins."""
    from sweep3d.runner import builtin_catalogue
    from sweep3d.spec import read_spec

    return read_spec(spec, builtin_catalogue(), base)
