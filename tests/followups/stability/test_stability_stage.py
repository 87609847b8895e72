"""The stability check through the runner's stages gives the rows the check gave when it read
the images and called the model itself: the same keys, and per key the same verdicts and margins
(the reference below is that direct path: each image loaded, or made again from its render when
it was not stored, and the baseline and every change predicted in the check's own batches)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sweep3d.cache.store import Store
from tests.helpers import load_spec

COLUMNS = ("stability_key", "pred_key", "image_key", "change", "seed", "base_correct", "base_margin", "correct",
           "margin", "flipped")


def _direct_rows(spec, store: Store, pred_keys: list[str], seed: int) -> list[dict]:
    """The rows of ``pred_keys`` (in sample order) as the check computed them before the runner."""
    from sweep3d.cache import load_image
    from sweep3d.core import from_uint8, to_uint8
    from sweep3d.followups.stability import check
    from sweep3d.followups.stability.changes import changed
    from sweep3d.runner import plan_spec
    from sweep3d.stages.infer import ModelHandle, object_class_ids, predict
    from sweep3d.stages.postprocess import make_image, post_controls, truth_digests

    handle = ModelHandle.resolve(spec, spec.spec.all_models[0])
    plan = plan_spec(spec, handle)
    by_key = {job.pred_key: job for job in plan.jobs}
    jobs = [by_key[k] for k in pred_keys]
    changes = check._applicable(handle, plan)
    wanted = {(k, c): check.stability_key(k, c, seed) for k in pred_keys for c in changes}
    model = handle.classifier()
    truths = object_class_ids(plan, model.label_map(), handle.name)
    digests = {t: store.digests(t) for t in ("renders", "images")}
    post, passes = post_controls(plan), truth_digests(store)
    batch = max(1, spec.spec.all_models[0].batch_size // (1 + len(changes)))
    rows = []
    for start in range(0, len(jobs), batch):
        part = jobs[start:start + batch]
        pixels = []
        for job in part:
            recorded = digests["images"].get(job.image_key)
            image = load_image(store, job.image_key, recorded) if recorded else None
            pixels.append(to_uint8(image) if image is not None else
                          make_image(store, plan, job, post, digests["renders"].get(job.render_key), passes).pixels)
        base = predict(model, from_uint8(np.stack(pixels)), handle.name)
        answers = {}
        for change in changes:
            if change == "resize":
                answers[change] = predict(check._other_arithmetic(model), from_uint8(np.stack(pixels)), handle.name)
            else:
                moved = [changed(p, change, seed, job.image_key) for p, job in zip(pixels, part)]
                answers[change] = predict(model, from_uint8(np.stack(moved)), handle.name)
        rows += check._rows(part, [truths[j.object] for j in part], base, answers, seed, wanted)
    return rows


def test_the_check_through_the_runner_gives_the_direct_rows(tiny_copy: Path) -> None:
    """The tiny run keeps its images in memory: the check makes them again from the renders (a
    blur of 0 leaves the render as the image: read as it is)."""
    from sweep3d.followups.stability import check_stability

    spec_path = tiny_copy / "spec.toml"
    spec = load_spec(spec_path)
    checked = check_stability(spec, sample=3, seed=5, scene=False)
    assert checked[0].computed == 3 and checked[0].cached == 0
    stored_rows = Store(tiny_copy / "store").table("stability").to_pylist()
    sampled = list(dict.fromkeys(r["pred_key"] for r in stored_rows))
    got = {r["stability_key"]: tuple(r[c] for c in COLUMNS) for r in stored_rows}
    want = {r["stability_key"]: tuple(r[c] for c in COLUMNS) for r in _direct_rows(spec, Store(tiny_copy / "store"),
                                                                                    _sample_order(spec, sampled), 5)}
    assert got == want and len(got) == 3 * len(sampled)


def _sample_order(spec, keys: list[str]) -> list[str]:
    """``keys`` in the order the check sampled them (its batches are made in that order)."""
    from sweep3d.followups.stability import check
    from sweep3d.results import results_store

    with results_store(spec) as reading:
        rows = check._sampled_results(reading, spec, None)
    order = check.stratified_sample(rows, len(keys), 5)
    assert set(order) == set(keys)
    return order


def test_the_rounds_add_images_only_while_bins_are_undecided_and_reuse_what_is_stored(tiny_copy: Path) -> None:
    """With a cap above the first sample, undecided bins get more images (a tiny run decides
    little, so the check goes on while images are left); a second check infers nothing."""
    from sweep3d.followups.stability import check_stability
    from sweep3d.followups.stability.sequential import UNDECIDED

    spec = load_spec(tiny_copy / "spec.toml")
    (first,) = check_stability(spec, sample=2, seed=5, max_sample=8, scene=False)
    rounds = first.rounds
    assert rounds is not None and 2 <= rounds.sample <= 8 and rounds.rounds >= 1
    assert first.computed == rounds.sample and len(rounds.decisions) == len(first.bins)
    assert rounds.stopped in ("decided", "exhausted", "cap")
    if rounds.stopped == "decided":
        assert not rounds.undecided()
    else:
        assert any(d == UNDECIDED for d, _, _ in rounds.decisions)
    least, most = first.fragile_range
    assert least <= first.fragile_failures <= most <= first.failures
    (again,) = check_stability(spec, sample=2, seed=5, max_sample=8, scene=False)
    assert again.computed == 0 and again.cached == again.sampled == rounds.sample
