"""Results read through a spec are that spec's: the jobs they join are its own plan's, not those
of whatever last ran under its experiment's name (another version of the spec, a notebook cell
edited and not run).

A run records its jobs (the experiment's jobs file, which ``results`` joins) with the identity of
the spec it ran (:func:`~sweep3d.driver.plugin_code.spec_identity`: its text as loaded, its included
files', its plug-ins' code). :func:`results_store` gives the store as it is when that identity
is the loaded spec's (a look at the file's metadata: a query or report after a run pays nothing
more), or when the file records none (a store last run before runs recorded it, or a jobs table
written by hand: read as before). Otherwise the experiment last ran another spec: the loaded one
is planned as a run would plan it (seconds at 10⁶ jobs) and the views join that plan's jobs,
written to a temporary file. Results are shared by key, so whatever of them any run made is
there; the jobs still without one are named in a warning, or an error when none has one, with
the command that makes them.

What the identity leaves out is trusted as before: a mesh's, texture's or design table's content,
a model's weights, or the Blender or sweep3d version changed since the last run.
"""

from __future__ import annotations

import logging
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from sweep3d.cache import Store
from sweep3d.core import UserError
from sweep3d.driver import recorded_identity, spec_identity
from sweep3d.spec import LoadedSpec

log = logging.getLogger("sweep3d.results")


class PlannedStore(Store):
    """The store, with ``experiment``'s jobs file replaced by ``jobs`` (its loaded spec's own plan)."""

    def __init__(self, root: Path, experiment: str, jobs: Path, warn: bool = True) -> None:
        super().__init__(root, warn=warn)
        self.experiment, self.jobs = experiment, jobs

    def jobs_path(self, experiment: str) -> Path:
        return self.jobs if experiment == self.experiment else super().jobs_path(experiment)


@contextmanager
def results_store(spec: LoadedSpec, warn: bool = True) -> Iterator[Store]:
    """The store whose ``jobs`` for ``spec``'s experiment are ``spec``'s own (see the module).
    ``warn``: warn of each file it reads around (False for a reader that refuses instead: see
    :meth:`~sweep3d.cache.store.Store.require_readable`).

    Raises:
        UserError: the experiment last ran another spec and none of this one's jobs has a result.
    """
    store = Store(spec.store, warn=warn)
    if not last_run_is_another(spec, store):
        yield store
        return
    with tempfile.TemporaryDirectory(prefix="sweep3d-jobs-") as folder:
        planned = PlannedStore(spec.store, spec.name, Path(folder) / store.jobs_path(spec.name).name, warn)
        write_own_jobs(spec, planned)
        check_results(spec, planned)
        yield planned


def last_run_is_another(spec: LoadedSpec, store: Store) -> bool:
    """Whether the experiment's jobs file records a spec other than ``spec`` (False without one)."""
    recorded = recorded_identity(store.jobs_path(spec.name))
    return recorded is not None and recorded != spec_identity(spec)


def write_own_jobs(spec: LoadedSpec, planned: PlannedStore) -> None:
    """Write ``spec``'s plans, as a run would record them, to ``planned``'s jobs file."""
    from sweep3d.runner import jobs_table, plans_as_run  # planning: only for another spec's store

    planned.write_table_file(planned.jobs, jobs_table(plans_as_run(spec, planned)))


def check_results(spec: LoadedSpec, store: Store) -> None:
    """Warn about the jobs of ``store``'s jobs file that have no result yet; refuse when none has."""
    missing, total = missing_results(store, spec.name)
    if not missing:
        return
    how = run_hint(spec)
    if missing == total:
        raise UserError(f"no results for this version of experiment {spec.name!r} in {store.root}: the experiment "
                        f"last ran another version of the spec, and none of this one's {total} jobs has a result "
                        f"yet; {how}")
    log.warning(f"warning: experiment {spec.name!r} last ran another version of the spec: the results shown are "
                f"this one's, but {missing} of its {total} jobs have none yet and are left out; {how}")


def missing_results(store: Store, experiment: str) -> tuple[int, int]:
    """How many rows of the experiment's jobs table have no prediction in ``store``, of how many."""
    files = store.view_files(experiment)
    con = store.connect(experiment, files)
    try:
        total = con.execute("SELECT count(*) FROM jobs").fetchone()[0]
        if "predictions" not in files:
            return total, total
        missing = con.execute("SELECT count(*) FROM jobs ANTI JOIN predictions USING (pred_key)").fetchone()[0]
    finally:
        con.close()
    return missing, total


def run_hint(spec: LoadedSpec) -> str:
    """How to make ``spec``'s results: its run, as the command line or Python calls it."""
    if str(spec.path).startswith("<"):  # <dict>, <string>: no file to name
        return "run it: call .run() on the experiment"
    return f"run it: sweep3d run {spec.path} (in Python: .run() on the experiment)"
