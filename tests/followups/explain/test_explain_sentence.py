"""The words a user reads of each fix (no render): the sentence states the margin, whether the
stability check's rule calls the fix fragile and what the search did about it, and the search's
resolution in each parameter's own units; the console prints the sentences of the nearest fixes,
how many more there are and where to read them, through ``sweep3d explain`` itself."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rich.console import Console
from typer.testing import CliRunner

from sweep3d.cli import app
from sweep3d.followups.explain.run import SHOWN, ExplainResult, _changes, _resolutions, explained_lines, scene_axes
from sweep3d.followups.explain.search import Config, Fix, Move
from sweep3d.followups.explain.sentence import fix_sentence, share_words
from sweep3d.spec.space import Point
from tests.helpers import TINY_SPEC, examples, load_spec, write_spec


def row(**changes: Any) -> dict[str, Any]:
    """A counterfactuals row of a found fix: +14 yaw over a 0..360 range, searched to 1/64."""
    base = dict(found=True, complete=True, failure_job=3, object="box", environment="white", distance=14 / 360,
                parameters=["orientation_yaw"], from_values=["10"], to_values=["24"], deltas=[14.0],
                shares=[14 / 360], fix_label="toaster", true_labels="toaster", fix_margin=0.31, fix_fragile=None,
                fragile_threshold=None, further_probes=0, nearest_distance=None, nearest_margin=None,
                nearest_change=None, resolution=1 / 64, resolutions=[360 / 64])
    return {**base, **changes}


def test_the_sentence_states_the_margin_and_the_searchs_resolution_in_the_parameters_units() -> None:
    assert fix_sentence(row()) == ("+14 orientation_yaw makes it a toaster "
                                   "(margin +0.31; nearest to within 1/64 of the range: orientation_yaw 5.62)")
    two = row(parameters=["blur_sigma", "orientation_yaw"], from_values=["1.5", "10"], to_values=["0.9", "24"],
              deltas=[-0.6, 14.0], resolutions=[3 / 64, 360 / 64])
    assert fix_sentence(two).endswith("nearest to within 1/64 of each range: blur_sigma 0.0469, orientation_yaw 5.62)")
    option = row(parameters=["camera_lens"], from_values=["wide"], to_values=["tele"], deltas=[None],
                 resolutions=[None])
    assert fix_sentence(option) == "camera_lens wide → tele makes it a toaster (margin +0.31)"  # an option is exact
    assert fix_sentence(row(found=False)) is None


def test_a_fragile_fix_says_so_and_what_the_search_did_about_it() -> None:
    fragile = row(fix_margin=0.012, fix_fragile=True, fragile_threshold=0.05, further_probes=6)
    assert fix_sentence(fragile) == (
        "+14 orientation_yaw makes it a toaster (fragile: margin +0.012, below the stability check's 0.05, and none "
        "of 6 probes further along the change clears it; nearest to within 1/64 of the range: orientation_yaw 5.62)")
    assert "clears it before the budget ended;" in fix_sentence({**fragile, "further_probes": 2, "complete": False})
    assert "and the budget ended before the search could go further" in fix_sentence(
        {**fragile, "further_probes": 0, "complete": False})
    flipped = row(fix_margin=0.4, fix_fragile=True, fragile_threshold=0.05, further_probes=1)
    assert "fragile: margin +0.4, its image flipped in the stability check" in fix_sentence(flipped)
    assert "margin +0.31, not fragile;" in fix_sentence(row(fix_fragile=False, fragile_threshold=0.05))


def test_a_sturdier_fix_past_the_nearest_names_the_nearest_and_its_margin() -> None:
    past = row(deltas=[20.0], fix_margin=0.21, fix_fragile=False, fragile_threshold=0.05, further_probes=3,
               nearest_distance=0.039, nearest_margin=0.012, nearest_change="+14 orientation_yaw")
    assert fix_sentence(past) == (
        "+20 orientation_yaw makes it a toaster (margin +0.21, not fragile; the nearest fix, +14 orientation_yaw "
        "at distance 0.039, is fragile: margin +0.012, below the stability check's 0.05; this is the first not "
        "fragile of 3 probes past it (1/64 of the range, then doubling))")
    assert fix_sentence({**past, "further_probes": 1}).endswith("; this is one search step (1/64 of the range) "
                                                                "past it)")


@settings(max_examples=examples(100), deadline=None)
@given(st.integers(2, 4096))
def test_a_resolution_of_one_over_n_is_written_as_a_fraction(n: int) -> None:
    assert share_words(1 / n) == f"1/{n}"
    assert share_words(0.3) == "0.3" and share_words(2 / 3) == "0.667"


def test_the_resolution_is_in_each_parameters_own_units(tmp_path: Path) -> None:
    """Yaw over −180..180 and blur over 0..1.5: 1/64 is 5.625° and 0.0234; an option has none."""
    body = TINY_SPEC.replace("yaw = [0, 45]", "yaw = { range = [-180, 180] }").replace(
        "sigma = [0.0, 1.5]", "sigma = { range = [0.0, 1.5] }")
    spec = load_spec(write_spec(tmp_path, body))
    space, axes = scene_axes(spec, ("box", "white"))
    assert [a.kind for a in axes] == ["range", "range"]
    failure = Config(("box", "white"), Point((0.98, 0.5), ()))
    fix = Fix(failure, Config(failure.scene, Point((0.02, 0.3), ())), (Move("blur_sigma", -0.2),
                                                                        Move("orientation_yaw", 0.04)),
              math.hypot(0.2, 0.04), 3, True)
    changes = _changes(space, fix)
    assert [c[0] for c in changes] == ["orientation_yaw", "blur_sigma"]
    assert _resolutions(space, fix, changes, 1 / 64) == pytest.approx([360 / 64, 1.5 / 64])
    logged = load_spec(write_spec(tmp_path, body.replace("sigma = { range = [0.0, 1.5] }",
                                                         "sigma = { range = [0.1, 10.0], log = true }")))
    space, _ = scene_axes(logged, ("box", "white"))
    sigma = space.continuous[1].space
    # on a log range, the step at the fix: from 1/64 before it (the side it came from) to it
    expected = abs(sigma.at(0.3) - sigma.at(0.3 + 1 / 64))
    assert _resolutions(space, fix, _changes(space, fix), 1 / 64) == pytest.approx([360 / 64, expected])
    assert expected != pytest.approx(9.9 / 64)


def rows(n: int, threshold: float | None) -> list[dict[str, Any]]:
    """``n`` found fixes (farther by job), every third fragile, the last one not found."""
    out = []
    for job in range(n):
        fragile = None if threshold is None else job % 3 == 0
        r = row(failure_job=job, object=f"o[red]{job}", distance=0.01 * (n - job), fix_margin=0.01 if fragile else 0.3,
                fix_fragile=fragile, fragile_threshold=threshold, further_probes=4 if fragile else 0)
        r["sentence"] = fix_sentence(r)
        out.append(r)
    out.append(row(failure_job=n, found=False, distance=None))
    return out


def plain(lines: list[str]) -> list[str]:
    """The lines as the console shows them (markup rendered, nothing wrapped)."""
    console = Console(record=True, width=400)
    for line in lines:
        console.print(line, highlight=False, soft_wrap=True)
    return console.export_text().splitlines()


def test_the_console_prints_the_nearest_fixes_sentences_and_how_many_more() -> None:
    found = rows(SHOWN + 3, 0.05)
    lines = plain(explained_lines(found, 0.05, 1 / 64, "my spec.toml"))
    assert lines[0].startswith("nearest fixes, nearest first (nearest to within 1/64 of each range changed")
    listed = lines[1:1 + SHOWN]
    nearest = sorted((r for r in found if r["found"]), key=lambda r: r["distance"])[:SHOWN]
    assert listed == [f"  o[red]{r['failure_job']} · white · job {r['failure_job']}: {r['sentence']}" for r in nearest]
    assert lines[1 + SHOWN] == ("  … and 3 more: the report's Nearest fixes panel, or sweep3d query 'my spec.toml' "
                                "\"SELECT failure_job, sentence FROM counterfactuals WHERE found ORDER BY distance\"")
    fragile = sum(r["fix_fragile"] is True for r in found)
    assert lines[-1].startswith(f"fragile: {fragile} of {SHOWN + 3} fixes (|margin| < 0.05, the stability check's")
    assert len(lines) == SHOWN + 3


def test_without_a_stability_check_the_console_says_fragility_is_unknown_and_how_to_know() -> None:
    lines = plain(explained_lines(rows(2, None), None, 1 / 64, "spec.toml"))
    assert len(lines) == 4 and not any("more:" in line for line in lines)  # all shown: no "more"
    assert lines[-1].startswith("fragile: unknown, no stability check of the model yet (run `sweep3d stability "
                                "spec.toml`, then explain again")
    assert plain(explained_lines([row(found=False)], None, 1 / 64)) == []


def test_sweep3d_explain_prints_the_sentences(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The command's own output, its search replaced by a result (the search itself needs renders:
    tests/followups/explain/test_explain.py)."""
    spec = write_spec(tmp_path, TINY_SPEC)
    found = rows(SHOWN + 2, 0.05)

    def searched(loaded, **kwargs) -> ExplainResult:
        assert loaded.path == spec
        return ExplainResult([], len(found), 40, 30, 30, 1.0, tmp_path / "store" / "tables" / "counterfactuals",
                             found, 0.05, 1 / 64)

    monkeypatch.setattr("sweep3d.followups.explain.explain_spec", searched)
    result = CliRunner().invoke(app, ["explain", str(spec), "--no-report"], env={"COLUMNS": "400"})
    assert result.exit_code == 0, result.output
    text = re.sub(r"\s+", " ", result.output)
    for r in sorted((r for r in found if r["found"]), key=lambda r: r["distance"])[:SHOWN]:
        assert f"o[red]{r['failure_job']} · white · job {r['failure_job']}: {r['sentence']}" in text
    assert "… and 2 more: the report's Nearest fixes panel, or sweep3d query" in text
    assert "fragile: 4 of 12 fixes" in text and "read them: sweep3d query" in text
