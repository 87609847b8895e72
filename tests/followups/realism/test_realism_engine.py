"""``sweep3d realism score --engine NAME``: the kit's design replayed with another renderer, its
verdicts matched back to the picked jobs by configuration and stored as source ``engine:NAME``.

No second engine ships yet (``[render] engine`` comes with the Mitsuba back-end), so the run of
the replaying spec is stood in for: the spec is written without its ``engine`` line, and the
run writes that experiment's jobs and predictions synthetically, numbered in another order than
the original run's (as a table policy numbers them scene by scene) with other image keys. What
is checked is everything around the renderer: the replaying spec (the table policy over the
kit's design, the original spec included), the matching back, the stored source and the view.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pyarrow as pa
import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.results.agreement import VERDICTS
from sweep3d.spec.columns import MODELS_METADATA, PARAMETERS_METADATA
from tests.helpers.realism import (
    LABELS,
    T0,
    agreement_rows,
    image_of,
    job_colours,
    make_run,
    redblue_row,
    stub_kit_tools,
)


@pytest.mark.torch  # its model module (tests/helpers/realism.py) is a torch module
def test_another_engine_is_a_source_matched_by_configuration(tmp_path: Path, monkeypatch) -> None:
    import sweep3d.followups.realism.score as score

    colours = job_colours(repeat=1)  # one job per configuration, as a run has
    sim = [redblue_row(image_of(c["rgb"]), LABELS[c["object"]])["correct"] for c in colours]
    spec = make_run(tmp_path, colours)
    stub_kit_tools(monkeypatch)
    assert CliRunner().invoke(app, ["realism", "pick", str(spec), "-o", str(tmp_path / "kit"),
                                    "--per-object", "4"]).exit_code == 0
    picked = json.loads((tmp_path / "kit" / "kit.json").read_text())["jobs"]
    flipped = set(picked[::3])  # the other engine disagrees on these
    written = {}

    def run(spec, console, wait, executor=None):
        """The replaying spec's run: one result per design row, numbered backwards."""
        written["spec"] = spec.path.read_text()
        assert spec.name == "realism.engine-mitsuba" and spec.spec.policy.type == "table"
        store = Store(spec.store)
        jobs, predictions = [], []
        for new, old in enumerate(reversed(picked)):
            c = colours[old]
            row = redblue_row(image_of(c["rgb"]), LABELS[c["object"]])
            if old in flipped:
                row = {**row, "correct": not row["correct"], "top1_label": "other"}
            key = f"e{new:03x}" + "cd" * 30
            jobs.append({"experiment": spec.name, "job": new, "object": c["object"],
                         "environment": c["environment"], "orientation_yaw": float(c["orientation_yaw"]),
                         "render_key": key, "image_key": key, "pred_key": f"p{key}", "model": "realism_model:redblue"})
            predictions.append({"pred_key": f"p{key}", "image_key": key, "model": "realism_model:redblue",
                                "model_digest": "d", "seconds": 0.0, "created_at": T0, **row})
        table = pa.Table.from_pylist(jobs).replace_schema_metadata(
            {PARAMETERS_METADATA: json.dumps(["orientation_yaw"]).encode(),
             MODELS_METADATA: json.dumps(["realism_model:redblue"]).encode()})
        store.write_table_file(store.jobs_path(spec.name), table)
        store.append("predictions", predictions)

    monkeypatch.setattr(score, "_run", run)
    result = CliRunner().invoke(app, ["realism", "score", str(spec), "--engine", "mitsuba", "--kit",
                                      str(tmp_path / "kit")])
    assert result.exit_code == 0, result.output
    replay = tomllib.loads(written["spec"])
    assert replay["policy"] == {"type": "table", "file": str((tmp_path / "kit" / "design.csv").resolve())}
    assert replay["include"] == [str(spec.resolve())]
    stored = Store(tmp_path / "store").table(VERDICTS).to_pylist()
    assert sorted(r["job"] for r in stored) == picked and {r["source"] for r in stored} == {"engine:mitsuba"}
    for r in stored:  # each verdict is the other engine's on the same configuration, under the picked job's id
        assert r["correct"] == (sim[r["job"]] != (r["job"] in flipped)) and r["image_key"].startswith("e")
    overall = next(r for r in agreement_rows(tmp_path) if r["overall"])
    assert (overall["source"], overall["n"], overall["n_agree"]) == ("engine:mitsuba", len(picked),
                                                                     len(picked) - len(flipped))
    assert f"agrees with the render's on {len(picked) - len(flipped)} of {len(picked)} jobs" in result.output


def test_an_engine_the_spec_cannot_take_is_one_line(tmp_path: Path, monkeypatch) -> None:
    spec = make_run(tmp_path)
    stub_kit_tools(monkeypatch)
    assert CliRunner().invoke(app, ["realism", "pick", str(spec), "-o", str(tmp_path / "kit")]).exit_code == 0
    for args, words in ((["--engine", "../x"], "use one of cycles, mitsuba"),
                        (["--engine", "mitsuba", str(tmp_path / "kit")], "leave PHOTOS and --match out"),
                        (["--engine", "povray"], "use one of cycles, mitsuba"),
                        ([], "give the folder of photographs")):
        result = CliRunner().invoke(app, ["realism", "score", str(spec), *args, "--kit", str(tmp_path / "kit")])
        assert result.exit_code == 2 and words in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1
    assert not Store(tmp_path / "store").segments(VERDICTS)
    assert not (tmp_path / "kit" / "engines").exists()  # a refused engine leaves nothing in the kit
