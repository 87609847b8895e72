"""The runner: the one place that wires stages, for every computation.

A computation (a run, the bench, the contact sheet, a follow-up) hands the runner plans: the jobs
(a :class:`~sweep3d.driver.Plan`, as its listing policy gave them), which of the standard stages
they go through (render → postprocess → infer), its own extra stages after them (the stability
check's), and it reads what they recorded. The runner does the rest the same way for each: the
store's writer lock, what killed commands left, the executor (a Ray session when it is Ray's: so
every computation runs on ``--executor ray`` with no code of its own), the progress bars, the
model tried before anything renders, and resuming (each stage computes only the keys the store
lacks: :mod:`sweep3d.driver.loop`). Its stages stay open between plans, so a search that asks
round after round keeps its Blender workers warm.
"""

from __future__ import annotations

from contextlib import ExitStack, contextmanager
from contextvars import ContextVar
from typing import Iterator, Mapping, Sequence

from rich.console import Console

from sweep3d.cache import Store
from sweep3d.driver import Found, Plan, RunProgress, StageOutcome, run_stages
from sweep3d.spec import LoadedSpec
from sweep3d.stages.infer import InferStage, ModelHandle, pending_predictions
from sweep3d.stages.postprocess import ImageHandoff, PostprocessStage
from sweep3d.stages.render import LOCAL, Executor, RenderInfo, RenderStage

#: The standard stages, in order: what a run computes of each job.
STANDARD = ("render", "postprocess", "infer")
#: The runner of the follow-up session now open (:func:`session`), if any.
_SESSION: ContextVar["Runner | None"] = ContextVar("sweep3d_runner_session", default=None)


class Runner:
    """The stages of one computation over one store, and how they are run (see the module).

    Made by :func:`running`, which holds the lock and the executor's session; made alone, it
    only says which stages a plan would go through (``sweep3d plan`` counts them).
    """

    def __init__(self, spec: LoadedSpec, store: Store, executor: Executor = LOCAL,
                 progress: RunProgress | None = None, keep_open: bool = False, console: Console | None = None) -> None:
        self.spec, self.store, self.executor = spec, store, executor
        self.post = PostprocessStage.for_spec(spec, ImageHandoff())
        self._progress, self._console = progress, console
        self._keep_open = keep_open
        self._render: RenderStage | None = None
        self._every_image: PostprocessStage | None = None  # see stages(every_image=True)
        self._infers: dict[tuple[str, str, bool, bool], InferStage] = {}
        self._prepared: set[int] = set()
        self._stack = ExitStack()

    @property
    def render(self) -> RenderStage:
        """The render stage on the runner's executor (made on first use)."""
        if self._render is None:
            self._render = RenderStage(self.executor, keep_open=self._keep_open)
        return self._render

    @property
    def progress(self) -> RunProgress:
        """The progress bars every plan's stages share (started on first use)."""
        if self._progress is None:
            self._progress = self._stack.enter_context(RunProgress(self._console))
        return self._progress

    def infer(self, model: ModelHandle, several: bool = False, every_image: bool = False) -> InferStage:
        """The infer stage of ``model`` (one per model, kept: the model loads once, also for another
        plan's handle of the same model, by its digest); ``every_image``: the one after
        :meth:`stages`' every-image postprocess, reading the images from the store."""
        found = (model.digest, model.label, several, every_image)
        stage = self._infers.get(found)
        if stage is None:
            post = self._post(every_image)
            stage = self._infers[found] = InferStage(
                model, on_ray=self.executor.kind == "ray", several=several, handoff=post.handoff,
                images_stored=post.store_images)
        return stage

    def stages(self, model: ModelHandle | None = None, names: Sequence[str] = STANDARD, extra: Sequence = (),
               several: bool = False, every_image: bool = False,
               timings: dict[str, RenderInfo] | None = None) -> tuple:
        """The standard stages ``names`` (in their order), then the computation's ``extra`` ones.

        Args:
            every_image: a postprocess stage that stores every image whatever the spec's ``[postprocess]
                store`` says, for a computation that reads them back (the contact sheet's tiles, the
                bench's errors against its reference).
            timings: a render stage of this call's own that records each render's timing there
                (the bench: a worker started for each turn, its scene loads timed apart).
        """
        unknown = [n for n in names if n not in STANDARD]
        if unknown or ("infer" in names and model is None):
            raise ValueError(f"stages {list(names)}: name some of {list(STANDARD)} (infer needs a model)")
        made = {"render": lambda: self.render if timings is None else RenderStage(self.executor, timings=timings),
                "postprocess": lambda: self._post(every_image),
                "infer": lambda: self.infer(model, several, every_image)}  # type: ignore[arg-type]
        return tuple(made[n]() for n in STANDARD if n in names) + tuple(extra)

    def _post(self, every_image: bool) -> PostprocessStage:
        if not every_image:
            return self.post
        if self._every_image is None:
            self._every_image = PostprocessStage()
        return self._every_image

    def prepare(self, plan: Plan, stages: Sequence) -> None:
        """Load each infer stage's model and try it, once, where ``plan`` has something to infer:
        a broken model fails in seconds, before anything renders."""
        for stage in stages:
            if isinstance(stage, InferStage) and id(stage) not in self._prepared \
                    and pending_predictions(plan, self.store, stage):
                stage.prepare(plan, self.store)
                self._prepared.add(id(stage))

    def run(self, plan: Plan, model: ModelHandle | None = None, *, stages: Sequence = STANDARD,
            extra: Sequence = (), several: bool = False, strict: bool = False, overlap: bool = True,
            found: Mapping[str, Found] | None = None, every_image: bool = False,
            timings: dict[str, RenderInfo] | None = None) -> list[StageOutcome]:
        """Run ``plan`` through ``stages`` (standard names, or stage objects of the caller's own
        making), then ``extra``; returns each one's outcome.

        Args:
            every_image, timings: which variant of the standard stages (see :meth:`stages`).
            strict: a failed key raises (see :func:`~sweep3d.driver.run_stages`).
            overlap: the stages run together, each on what the ones before have stored so far.
            found: what the caller already looked up, by table (see ``run_stages``).
        """
        names = [s for s in stages if isinstance(s, str)]
        own = [s for s in stages if not isinstance(s, str)]
        chosen = ((*self.stages(model, names, several=several, every_image=every_image, timings=timings), *own, *extra)
                  if names else (*own, *extra))
        self.prepare(plan, chosen)
        return run_stages(chosen, plan, self.store, self.progress, strict=strict, overlap=overlap, found=found)

    def close(self) -> None:
        """Stop what the stages keep open (workers started ahead, the process answering near
        ties), and the progress bars."""
        try:
            if self._render is not None:
                self._render.close()
            for stage in self._infers.values():
                stage.close()
        finally:
            self._stack.close()


@contextmanager
def running(spec: LoadedSpec, *, executor: Executor = LOCAL, wait: float = 0.0, console: Console | None = None,
            progress: RunProgress | None = None, store: Store | None = None, keep_open: bool = False,
            leftovers: bool = True) -> Iterator[Runner]:
    """A :class:`Runner` for ``spec``'s store, holding its writer lock (``wait``: seconds to wait
    for another command's) within the executor's session, what killed commands left removed first
    (``leftovers``). ``progress``: bars the caller shows already (else the runner's own, on
    ``console``)."""
    from sweep3d.runner.pipeline import remove_leftovers

    store = store or Store(spec.store)
    shared = _SESSION.get()
    if shared is not None and shared.store.root == store.root and shared.executor == executor and progress is None:
        yield shared  # within a session: its lock, its warm workers and loaded models
        return
    with ExitStack() as stack:
        if executor.kind == "ray":
            from sweep3d.stages.render import ray_session

            stack.enter_context(ray_session(executor.address))  # joined when something renders or infers
        stack.enter_context(store.lock(wait))
        if leftovers:
            remove_leftovers(store)  # before anything is written
        runner = Runner(spec, store, executor, progress, keep_open, console)
        stack.callback(runner.close)
        yield runner


@contextmanager
def session(spec: LoadedSpec, *, executor: Executor = LOCAL, wait: float = 0.0,
            console: Console | None = None) -> Iterator[Runner]:
    """One runner for a follow-up's several computations over ``spec``'s store (its variants'
    plans, one after another): each :func:`running` within it on the same store and executor is
    this runner, so the render workers stay warm between plans of the same render settings and
    each model loads once (``sweep3d grade``'s checks: a dozen plans, each of which would start
    Blender and load the model again). The plans must share the spec's post-processing."""
    with running(spec, executor=executor, wait=wait, console=console, keep_open=True) as runner:
        token = _SESSION.set(runner)
        try:
            yield runner
        finally:
            _SESSION.reset(token)
