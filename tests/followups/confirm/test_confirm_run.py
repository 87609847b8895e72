"""``sweep3d confirm`` end to end on a tiny real spec (32 px, one sample): fresh twins rendered
through the normal stages, none an image of the run, a rerun that renders nothing, the verdict
recorded for ``run``'s findings."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep3d.cache.store import Store
from sweep3d.cli import app
from sweep3d.followups.confirm.claims import boundary_claim
from sweep3d.followups.confirm.record import read_verdicts
from sweep3d.followups.confirm.run import SUFFIX, confirm
from sweep3d.results.confirmation import UNCONFIRMED
from sweep3d.spec.params import Range
from tests.helpers import load_spec, write_spec
from tests.helpers.planted import FRESH_SPEC as SPEC
from tests.helpers.planted import bright_spec

pytestmark = [pytest.mark.slow, pytest.mark.blender, pytest.mark.torch]



def test_confirm_renders_fresh_matched_twins_once_and_records_the_verdict(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, SPEC)
    ran = CliRunner().invoke(app, ["run", str(spec), "--no-report"])
    assert ran.exit_code == 0, ran.output
    loaded = load_spec(spec)
    store = Store(loaded.store)
    discovery = {r[0] for r in store.connect("fresh").execute("SELECT image_key FROM jobs").fetchall()}
    row = {"parameter": "orientation_yaw", "scope": "all", "object": None, "environment": None, "fails": "below",
           "boundary": 0.0, "values": 4, "boundary_low": -10.0, "boundary_high": 10.0}
    claim = boundary_claim(row, "orientation_yaw fails below 0", Range(-180.0, 180.0))

    first = confirm(loaded, renders=4, claims=[claim])
    assert first.rendered == 4 and first.failed == 0
    (made,) = first.confirmations
    # two pairs: too few for any outcome to confirm it, so neither confirmed nor refuted
    assert made.drawn == 2 and made.verdict.pairs == 2 and made.verdict.status == UNCONFIRMED
    jobs = store.connect("fresh" + SUFFIX).execute(
        "SELECT job, image_key, orientation_yaw, orientation_pitch FROM jobs ORDER BY job").fetchall()
    assert len(jobs) == 4 and not {j[1] for j in jobs} & discovery  # never an image of the run
    for inside, outside in (jobs[0:2], jobs[2:4]):
        assert inside[2] < 0 <= outside[2] and inside[3] == outside[3]  # matched on the pitch
    assert read_verdicts(store, "fresh")[claim.key]["verdict"]["pairs"] == 2

    again = confirm(loaded, renders=4, claims=[claim])
    assert again.rendered == 0 and again.cached == 4
    assert again.confirmations[0].verdict == made.verdict

    printed = CliRunner().invoke(app, ["confirm", str(spec), "--renders", "4", "--max-renders", "4"])
    assert printed.exit_code == 0, printed.output
    assert "no significant finding to confirm" in printed.output or "fresh renders:" in printed.output


def test_confirm_before_any_run_is_one_line(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, SPEC)
    result = CliRunner().invoke(app, ["confirm", str(spec)])
    assert result.exit_code == 2
    assert "sweep3d run" in result.output and "Traceback" not in result.output




def test_a_real_boundary_is_confirmed_and_run_marks_it(tmp_path: Path) -> None:
    """A model that fails on dark images: the run finds the brightness boundary, confirm replicates
    it on fresh twins, a second confirm renders nothing, and run's findings say confirmed."""
    spec = bright_spec(tmp_path)
    runner = CliRunner()
    first = runner.invoke(app, ["run", str(spec), "--no-report"])
    assert first.exit_code == 0, first.output
    assert "brightness_contrast_brightness fails below" in first.output and "[untested]" in first.output
    confirmed = runner.invoke(app, ["confirm", str(spec), "--renders", "24", "--max-renders", "24"])  # one look
    assert confirmed.exit_code == 0, confirmed.output
    assert "confirmed: brightness_contrast_brightness fails below" in confirmed.output
    assert "fresh jobs: 24, renders 12 made" in confirmed.output  # twins differ in a post control: one render
    again = runner.invoke(app, ["confirm", str(spec), "--renders", "24", "--max-renders", "24"])
    assert "renders 0 made and 12 cached" in again.output
    marked = runner.invoke(app, ["run", str(spec)])
    assert "[confirmed on 12 fresh pairs" in " ".join(marked.output.split())
    html = (tmp_path / "store" / "reports" / "fresh.html").read_text(encoding="utf-8")
    assert "confirm: <b>confirmed</b> on 12 fresh pairs" in html  # in the finding's evidence, a click away
