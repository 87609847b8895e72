"""``sweep3d realism pick``: choose the jobs worth photographing and write the kit to do it.

Per object and model, half of the chosen results are ones the model got right and half ones
it got wrong (as the 3DB paper's physical study did: 5 and 5), drawn with a seeded generator
and spread over environments and control values (each pick prefers the values picked least so
far). Near ties — the true class and the best other class within :data:`NEAR_TIE` probability
— are coin flips that an invisible change flips, so they are left out (or, with
``near_ties="mark"``, kept and flagged in ``kit.json``).

The kit folder (default ``kits/<experiment>`` in the store) holds ``design.csv`` (the picked
jobs' configurations; a spec whose ``[policy]`` is ``type = "table"``, ``file = "design.csv"``
renders them again), ``renders/<job>.png`` (the job's raw render, byte for byte: what a camera
in the room sees, before the job's 2D controls — blur, noise, ... — which ``score`` applies to
the photograph exactly once, as the postprocess stage applied them to the render),
``edges/<job>.png`` (its edges, to lay over the live camera view), ``align.html`` (the page that
does so and saves each photograph as ``<job>.jpg``) and ``kit.json`` (what was picked and why).
Same store, spec and seed: the same bytes.
"""

from __future__ import annotations

import errno
import io
import json
import os
import random
import shutil
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pyarrow as pa

from sweep3d.assets import not_a_file
from sweep3d.cache import Store, safe_filename
from sweep3d.core import UserError
from sweep3d.followups.realism.stored import KITS_FOLDER
from sweep3d.spec import LoadedSpec

#: |p(true) − p(best other)| below this is a near tie: a verdict an imperceptible change flips.
NEAR_TIE = 0.05
KIT = "kit.json"
DESIGN = "design.csv"
RENDERS, EDGES = "renders", "edges"
ALIGN = "align.html"
KIT_VERSION = 2  # 2: renders/ holds raw renders (1 held them after the 2D controls, which score applied again)
NEAR_TIES = ("leave", "mark")


def margin(row: dict[str, Any]) -> float | None:
    """A result's margin: the probability of its true class(es) less that of the best other class
    (negative for a failure); None when the store holds neither a ``margin`` column nor ranked
    probabilities (a task that is not classification).

    Reads the ``margin`` column where results have one; else works it out from ``label_prob``,
    ``topk`` and ``topk_probs`` (the best other class is the first ranked class that is not one
    of ``label_ids``; when all of the top k are true classes, the k-th probability bounds it).
    """
    if row.get("margin") is not None:
        return float(row["margin"])
    truth, ranked, probs = row.get("label_prob"), row.get("topk"), row.get("topk_probs")
    if truth is None or not ranked or not probs:
        return None
    true_ids = set(row.get("label_ids") or [])
    if not true_ids and row.get("top1") is not None and row.get("correct"):
        true_ids = {row["top1"]}
    other = next((p for i, p in zip(ranked, probs) if i not in true_ids), probs[-1])
    return float(truth) - float(other)


def near_tie(row: dict[str, Any], threshold: float = NEAR_TIE) -> bool:
    """Whether a result's verdict is a near tie (see :func:`margin`), or one the stability check
    calls fragile (``sweep3d stability``: a change no eye sees flips verdicts that near)."""
    m = margin(row)
    return row.get("fragile") is True or (m is not None and abs(m) < threshold)


@dataclass(frozen=True)
class Pick:
    """One picked result: its job, model and what the simulation said."""

    job: int
    model: str
    object: str
    environment: str
    correct: bool
    top1_label: str | None
    margin: float | None
    near_tie: bool
    image_key: str


@dataclass(frozen=True)
class Kit:
    """What ``pick`` wrote: the folder, the picks, and per (model, object) how many it wanted and found."""

    folder: Path
    picks: list[Pick]
    jobs: list[int]
    short: list[str]  # one line per (model, object) with fewer right or wrong results than asked for
    near_ties_left_out: int

    def line(self) -> str:
        ties = f"; {self.near_ties_left_out} near ties left out" if self.near_ties_left_out else ""
        return (f"picked {len(self.picks)} results ({len(self.jobs)} jobs to photograph){ties}: open "
                f"{self.folder / ALIGN} on a phone, or print {self.folder / RENDERS}")


def default_kit(spec: LoadedSpec) -> Path:
    """``kits/<experiment>`` in the store: beside the spec, a kit of renders would land in the
    user's repository (``git status`` would show it)."""
    return spec.store / KITS_FOLDER / safe_filename(spec.name)


def choose(rows: Sequence[dict[str, Any]], per_object: int, seed: int, parameters: Sequence[str],
           key: str = "") -> list[dict[str, Any]]:
    """``per_object`` of one (model, object)'s ``rows``: half right (rounded up), half wrong,
    each pick the seeded candidate whose environment and control values are the least picked so
    far (a draw that leaves a half short takes what there is). Deterministic in ``seed``, ``key``
    and the rows' order."""
    rng = random.Random(f"{seed}:{key}")
    ordered = sorted(rows, key=lambda r: r["job"])
    ranks = {r["job"]: rng.random() for r in ordered}
    right = [r for r in ordered if r["correct"]]
    wrong = [r for r in ordered if not r["correct"]]
    want_right = (per_object + 1) // 2
    want_wrong = per_object - want_right
    columns = ["environment", *parameters]
    used: dict[tuple[str, Any], int] = {}
    chosen: list[dict[str, Any]] = []
    for pool, want in ((right, want_right), (wrong, want_wrong)):
        pool = list(pool)
        for _ in range(min(want, len(pool))):
            best = min(pool, key=lambda r: (sum(used.get((c, _level(r.get(c))), 0) for c in columns), ranks[r["job"]]))
            pool.remove(best)
            chosen.append(best)
            for c in columns:
                used[(c, _level(best.get(c)))] = used.get((c, _level(best.get(c))), 0) + 1
    return sorted(chosen, key=lambda r: r["job"])


def _level(value: Any) -> Any:
    """A value as a level for spreading picks (floats rounded, so 0.1 + 0.2 is 0.3)."""
    return round(value, 6) if isinstance(value, float) else value


def pick(spec: LoadedSpec, output: Path | None = None, per_object: int = 10, seed: int | None = None,
         near_ties: str = "leave", threshold: float = NEAR_TIE) -> Kit:
    """Pick per object and model ``per_object`` results of ``spec``'s finished run and write the kit.

    Raises:
        UserError: a bad option, an output folder holding other files, no results, a damaged blob.
    """
    from sweep3d.results import arrow, results_connection, results_store, stored_parameters

    if per_object < 1:
        raise UserError(f"--per-object {per_object}: pick at least 1 result per object")
    if near_ties not in NEAR_TIES:
        raise UserError(f"--near-ties {near_ties!r}: use {' or '.join(NEAR_TIES)}")
    folder = check_kit_folder(Path(output) if output is not None else default_kit(spec), spec.store)
    seed = spec.spec.experiment.seed if seed is None else seed
    picked: list[tuple[dict[str, Any], Pick]] = []
    short: list[str] = []
    left_out = 0
    with results_store(spec) as store:
        parameters = stored_parameters(store.jobs_path(spec.name)) or list(spec.parameter_columns)
        for model in [m.label for m in spec.models]:
            with results_connection(spec, model if len(spec.models) > 1 else None, store=store) as con:
                table = arrow(con, _selection_sql(con))
            rows = table.to_pylist()
            for obj in [o.name for o in spec.objects]:
                candidates = [r for r in rows if r["object"] == obj]
                ties = [r for r in candidates if near_tie(r, threshold)]
                if near_ties == "leave":
                    left_out += len(ties)
                    candidates = [r for r in candidates if not near_tie(r, threshold)]
                chosen = choose(candidates, per_object, seed, parameters, f"{model}:{obj}")
                rights = sum(r["correct"] for r in chosen)
                if rights < (per_object + 1) // 2 or len(chosen) - rights < per_object // 2:
                    short.append(f"{model}, {obj}: {rights} right and {len(chosen) - rights} wrong results "
                                 f"(asked for {(per_object + 1) // 2} and {per_object // 2})")
                for r in chosen:
                    m = margin(r)
                    picked.append((r, Pick(int(r["job"]), model, obj, r["environment"], bool(r["correct"]),
                                           r.get("top1_label"), m, m is not None and abs(m) < threshold,
                                           r["image_key"])))
        if not picked:
            raise UserError(f"no counted results of {spec.name} to pick from: run `sweep3d run {spec.path}` first")
        first = _first_per_job(picked)
        images = {job: render_bytes(store, r, spec) for job, r in first.items()}
        design = _design_table(list(first.values()), parameters)
    _write_kit(folder, spec, seed, per_object, threshold, near_ties, [p for _, p in picked], images, design,
               parameters)
    return Kit(folder, [p for _, p in picked], sorted(images), short, left_out)


#: The column :func:`_selection_sql` adds: the recorded digest of the result's raw render.
RENDER_DIGEST = "_kit_render_sha256"


def _selection_sql(con) -> str:
    """Every counted result with its raw render's recorded digest (checked when the kit copies it)."""
    views = {name for name, in con.execute("SELECT view_name FROM duckdb_views() WHERE NOT internal").fetchall()}
    digest = ("(SELECT v.sha256 FROM renders v WHERE v.render_key = r.render_key LIMIT 1)"
              if "renders" in views else "NULL")
    return f"SELECT r.*, {digest} AS {RENDER_DIGEST} FROM results r WHERE r.counted ORDER BY r.job"


def render_bytes(store: Store, row: dict[str, Any], spec: LoadedSpec) -> bytes:
    """The raw render of ``row``'s job (its PNG blob, before the job's 2D controls), checked
    against its recorded digest: what a photograph of the scene should match.

    Raises:
        UserError: the result names no render, or its blob is missing, unreadable or damaged.
    """
    from sweep3d.cache import sha256_bytes

    key = row.get("render_key")
    if not key:
        raise UserError(f"job {row['job']} of {spec.name} names no render: run `sweep3d run {spec.path}` again, "
                        "then pick")
    path = store.blob_path(key)
    try:
        data = path.read_bytes()
    except OSError as exc:
        damaged = "is missing" if isinstance(exc, FileNotFoundError) else f"cannot be read ({exc.strerror})"
    else:
        digest = row.get(RENDER_DIGEST)
        damaged = "no longer matches its recorded digest" if digest and sha256_bytes(data) != digest else ""
    if damaged:
        raise UserError(f"the render of job {row['job']} ({path}) {damaged}: run `sweep3d run {spec.path}` again "
                        "to render it anew, then pick")
    return data


def _first_per_job(picked: list[tuple[dict[str, Any], Pick]]) -> dict[int, dict[str, Any]]:
    """One result row per picked job (the first model's): a job is photographed once for every model."""
    out: dict[int, dict[str, Any]] = {}
    for row, p in picked:
        out.setdefault(p.job, row)
    return dict(sorted(out.items()))


def _design_table(rows: list[dict[str, Any]], parameters: Sequence[str]) -> pa.Table:
    names = ["object", "environment", *(p for p in parameters if p in rows[0])]
    return pa.table({n: [r.get(n) for r in rows] for n in names})


def check_kit_folder(folder: Path, store: Path) -> Path:
    """``folder`` if a kit may be written there: new, empty, or an earlier kit (replaced whole).

    Raises:
        UserError: it is inside the store but not in its kits folder, a file, or a folder holding
            files that are not a kit.
    """
    real = Path(os.path.realpath(folder))
    if real.is_relative_to(os.path.realpath(store)) and not real.is_relative_to(os.path.realpath(store / KITS_FOLDER)):
        raise UserError(f"-o {folder}: inside the store {store}, whose files only sweep3d's runs write; "
                        f"choose a folder outside it, or leave -o out for {store / KITS_FOLDER}/<experiment>")
    if folder.exists() and not folder.is_dir():
        raise UserError(f"-o {folder}: is a file; name a folder for the kit")
    try:
        if folder.is_dir() and any(folder.iterdir()) and not (folder / KIT).is_file():
            raise UserError(f"-o {folder}: holds other files; choose a new or empty folder for the kit")
    except OSError as exc:
        raise UserError(f"-o {folder}: cannot be read ({exc.strerror or exc}); fix its permissions or choose "
                        "another folder for the kit") from None
    return folder


def _write_kit(folder: Path, spec: LoadedSpec, seed: int, per_object: int, threshold: float, near_ties: str,
               picks: list[Pick], images: dict[int, bytes], design: pa.Table, parameters: Sequence[str]) -> None:
    """Write the kit into a staging folder beside ``folder``, then put it in place whole.

    An earlier kit's photographs (``<job>.jpg`` and the like) stay: only the kit's own files are replaced.
    """
    from PIL import Image

    from sweep3d.stages.plan import write_design

    edge_image, write_align_page, align_shot = kit_tools()
    staging = folder.parent / f".{folder.name}.{uuid.uuid4().hex}.tmp"
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        (staging / RENDERS).mkdir(parents=True)
        (staging / EDGES).mkdir()
        write_design(design, parameters, staging / DESIGN)
        jobs = sorted(images)
        scenes = {p.job: p for p in picks}
        shots = []
        for job in jobs:
            name = f"{job}.png"
            (staging / RENDERS / name).write_bytes(images[job])
            with Image.open(io.BytesIO(images[job])) as im:
                rgb = np.asarray(im.convert("RGB"), dtype=np.uint8)
            edges = np.asarray(edge_image(rgb), dtype=np.uint8)
            buffer = io.BytesIO()
            Image.fromarray(edges, "RGBA").save(buffer, format="PNG")
            (staging / EDGES / name).write_bytes(buffer.getvalue())
            p = scenes[job]
            shots.append(align_shot(job_id=str(job), render=f"{RENDERS}/{name}", edges=f"{EDGES}/{name}",
                                    caption=f"job {job}: {p.object} in {p.environment}"))
        (staging / KIT).write_text(json.dumps(_kit_document(spec, seed, per_object, threshold, near_ties, picks),
                                              indent=1, allow_nan=False) + "\n", encoding="utf-8")
        write_align_page(staging, shots)
        _put_in_place(staging, folder)
    except OSError as exc:
        raise _unwritable(folder, exc) from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _unwritable(folder: Path, exc: OSError) -> UserError:
    """One line for ``exc``, met writing the kit into ``folder``: what the OS said and the fix."""
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        fix = "free some disk space, or write the kit to another disk with -o"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        fix = "make its folder writable, or write the kit elsewhere with -o"
    else:
        fix = "write the kit elsewhere with -o"
    return UserError(f"{folder}: cannot write the kit ({exc.strerror or exc}); {fix}")


def _put_in_place(staging: Path, folder: Path) -> None:
    """Move the staged kit's files into ``folder``, replacing an earlier kit's (photographs kept)."""
    folder.mkdir(parents=True, exist_ok=True)
    for entry in staging.iterdir():
        target = folder / entry.name
        if entry.is_dir() and target.is_dir():
            shutil.rmtree(target)
        os.replace(entry, target)


def _kit_document(spec: LoadedSpec, seed: int, per_object: int, threshold: float, near_ties: str,
                  picks: list[Pick]) -> dict[str, Any]:
    return {
        "version": KIT_VERSION, "experiment": spec.name, "seed": seed, "per_object": per_object,
        "near_tie": threshold, "near_ties": near_ties,
        "jobs": sorted({p.job for p in picks}),
        "picks": [{"job": p.job, "model": p.model, "object": p.object, "environment": p.environment,
                   "correct": p.correct, "top1_label": p.top1_label,
                   "margin": None if p.margin is None else round(p.margin, 6), "near_tie": p.near_tie}
                  for p in picks],
    }


def read_kit(folder: Path) -> dict[str, Any]:
    """A kit's ``kit.json``.

    Raises:
        UserError: the folder holds no kit, or its ``kit.json`` does not read.
    """
    path = folder / KIT
    kind = not_a_file(path)  # a FIFO's read would wait for a writer for ever
    if kind:
        raise UserError(f"{path}: is {kind}, not the kit sweep3d wrote; run `sweep3d realism pick` again")
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise UserError(f"{folder}: holds no {KIT}; run `sweep3d realism pick SPEC -o {folder}` first, or give "
                        "the kit's folder with --kit") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UserError(f"{path}: cannot be read ({exc}); run `sweep3d realism pick` again") from None
    if not isinstance(document, dict) or not isinstance(document.get("jobs"), list):
        raise UserError(f"{path}: is not a kit sweep3d wrote; run `sweep3d realism pick` again")
    return document


def kit_tools():
    """(``edge_image``, ``write_align_page``, ``AlignShot``): the kit's edge images and alignment
    page, from :mod:`sweep3d.followups.realism.edges` and :mod:`sweep3d.followups.realism.align`."""
    try:
        from sweep3d.followups.realism.align import AlignShot, write_align_page
        from sweep3d.followups.realism.edges import edge_image
    except ImportError as exc:  # pragma: no cover - both modules ship with sweep3d
        raise UserError(f"this sweep3d lacks the alignment page ({exc}); reinstall sweep3d") from None
    return edge_image, write_align_page, AlignShot
