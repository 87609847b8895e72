"""What ``sweep3d stability`` prints of a sequential check (built from a synthetic result, no run):
where it stopped and the error control, each undecided bin with the sample that would decide it,
and the fragile count as a lower bound with its range while bins remain undecided."""

from __future__ import annotations

from sweep3d.cli.stability import decision_cell, fragile_count_sentence, stop_sentence
from sweep3d.followups.stability.check import Checked
from sweep3d.followups.stability.sequential import needed, run_rounds


def _checked(rates_counts: list[tuple[int, int]], pools: list[int], cap: int, fragile_range: tuple[int, int],
             threshold_range: tuple[float, float]) -> Checked:
    rounds = run_rounds(pools, 64, cap, lambda taken: rates_counts)
    bins = [{"n": n, "flips": f, "lower": 0.0, "upper": 1.0} for n, f in rates_counts]
    return Checked("m", rounds.sample, rounds.sample, 0, [], bins, [], 0.5, 335, 68, rounds=rounds,
                   fragile_range=fragile_range, threshold_range=threshold_range)


def test_undecided_bins_make_the_count_a_lower_bound_with_its_range() -> None:
    found = _checked([(9, 2), (40, 30)], [9, 400], 1024, (68, 152), (0.01, 0.02))
    assert found.rounds.undecided() == [0] and found.rounds.stopped == "exhausted"
    sentence = fragile_count_sentence(found)
    assert sentence.startswith("fragile: at least 68 of 335 failures, a lower bound: 68 to 152 depending on 1 margin bin still undecided")
    assert "68 by the rule as it reads now" in sentence
    cell = decision_cell(found, 0)
    assert cell == (f"undecided: about {needed(2, 9, found.rounds.looks)} images of the bin would decide it at its "
                    "flip rate; the run has 9: a larger sweep would")
    assert decision_cell(found, 1) == "fragile"
    stop = stop_sentence(found, 1024)
    assert stop.startswith("stopped at 64 images after 1 of at most 5 rounds: no undecided margin bin has images left")
    assert "5% split over the 5 planned looks, Bonferroni" in stop and "99.00%" in stop


def test_a_decided_check_prints_the_count_as_a_figure() -> None:
    found = _checked([(40, 30), (200, 0)], [400, 400], 256, (68, 68), (0.01, 0.01))
    assert found.rounds.stopped == "decided"
    sentence = fragile_count_sentence(found)
    assert sentence.endswith("68 of 335 failures; every margin bin decided") and "at least" not in sentence
    assert "every margin bin decided against the rule" in stop_sentence(found, 256)
    assert decision_cell(found, 1) == "not fragile"


def test_the_cap_names_the_option_and_how_many_bins_are_undecided() -> None:
    found = _checked([(100, 11)], [100_000], 128, (0, 40), (0.0, 0.01))
    assert found.rounds.stopped == "cap"
    assert "the cap (--max-sample 128) reached with 1 margin bin undecided" in stop_sentence(found, 128)


def test_the_scene_lines_give_worst_of_neighbourhood_beside_plain_accuracy_and_what_did_not_move() -> None:
    from sweep3d.cli.stability import scene_lines
    from sweep3d.followups.stability.neighbours import Move
    from sweep3d.followups.stability.scene import SceneCheck
    from sweep3d.spec import Range

    found = _checked([(9, 0)] * 7, [100] * 7, 64, (68, 68), (0.5, 0.5))
    assert "not checked" in scene_lines(found)[0]  # --no-scene says so
    moves = [Move("orientation", "yaw", "angle", 1.0, Range(-180, 180), period=360.0, label="yaw"),
             Move("camera", "zoom", "closeness", 0.01, Range(1, 2), label="distance")]
    found.scene = SceneCheck(None, None, None, moves, {"blur_sigma": "applied to the image after rendering"},
                             planned=[None] * 12, rendered=10, cached=2, computed=9, out_of_frame=1)
    row = {"images": 4, "flipped": 1, "accuracy": 0.5, "accuracy_low": 0.15, "accuracy_high": 0.85,
           "worst_accuracy": 0.25, "worst_low": 0.05, "worst_high": 0.7}
    found.neighbourhood = [{**row, "object": None}, {**row, "object": "[red]mug"}]
    lines = scene_lines(found)
    assert lines[0] == ("scene neighbours (yaw ±1°, distance ±1%): 12 of the sampled images' neighbours, 2 compared "
                        "before, 9 now (10 renders made); 1 out of frame")
    assert "  not moved: blur_sigma: applied to the image after rendering" in lines
    assert any(line.startswith("worst-of-neighbourhood accuracy") and "25% (5%–70%) against 50% plain (15%–85%) "
               "over 4 sampled images; 1 flipped under a neighbour" in line for line in lines)
    assert "  [red]mug: 25% (5%–70%) against 50% plain (15%–85%) over 4" in lines  # printed escaped, as text
    found.neighbourhood = []
    assert "no sampled image has a neighbour compared yet" in scene_lines(found)[-1]
