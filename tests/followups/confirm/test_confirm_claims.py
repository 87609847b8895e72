"""A run's findings as claims, from a synthetic store (nothing rendered): the regions ``confirm``
draws its twins in are the ones the findings name, and an oracle that fails exactly there has
them confirmed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sweep3d.cache.store import Store
from sweep3d.followups.confirm.claims import Side
from sweep3d.followups.confirm.draw import draw_pairs, space_of
from sweep3d.followups.confirm.run import findings_claims
from sweep3d.results.boundaries import numeric_scales
from sweep3d.results.confirmation import CONFIRMED, judge, tally
from sweep3d.results.summary import named_rules, summarise
from tests.helpers import SPEC_ENVIRONMENTS, load_spec, make_store, spec_toml, write_spec

SPEC = spec_toml("e", render={"resolution": 32}, objects=(("obj", "cube.obj", ["carton"]),),
                 environments=(("env", SPEC_ENVIRONMENTS["white"]),), body="""\
[[controls]]
type = "camera"
elevation = { range = [0, 80] }

[[controls]]
type = "orientation"
yaw = { range = [-180, 180] }

[[controls]]
type = "blur"
sigma = [0.0, 1.5, 3.0]

[policy]
type = "random"
samples = 240
""")


def truth(row: dict) -> bool:
    """The model: right unless the camera is above 40° or the blur is the strongest."""
    return row["camera_elevation"] <= 40 and row["blur_sigma"] != 3.0


def test_the_findings_become_claims_that_a_true_oracle_confirms(tmp_path: Path) -> None:
    loaded = load_spec(write_spec(tmp_path, SPEC))
    rng = np.random.default_rng(5)
    rows = [{"camera_elevation": float(rng.uniform(0, 80)), "orientation_yaw": float(rng.uniform(-180, 180)),
             "blur_sigma": (0.0, 1.5, 3.0)[i % 3]} for i in range(240)]
    con = make_store(tmp_path, [{**r, "correct": truth(r)} for r in rows])
    columns = ["camera_elevation", "orientation_yaw", "blur_sigma"]
    summary = summarise(con, columns, scales=numeric_scales(loaded.controls))
    con.close()
    space = space_of(loaded)
    claims = findings_claims(loaded, Store(tmp_path / "store"), summary, space)
    by_key = {c.key: c for c in claims}
    assert "value blur_sigma = 3" in by_key
    assert by_key["value blur_sigma = 3"].inside == Side((3.0,))
    assert set(by_key["value blur_sigma = 3"].outside.options) == {0.0, 1.5}
    (boundary,) = [c for c in claims if c.key.startswith("boundary camera_elevation fails above")]
    (lo, hi), = boundary.inside.intervals
    assert 36 < lo < 44 and hi == 80
    for c in claims:
        if c.key.startswith("value camera_elevation"):  # a bin of the range: its edges are its label's
            (a, b), = c.inside.intervals
            assert c.key.endswith(f"{a:.0f}–{b:.0f}") and a >= 40 - 8
    assert any(c.key.startswith("value camera_elevation") for c in claims)
    assert len(claims) == len(summary.regions) + len(summary.boundaries) + len(named_rules(summary))
    pairs = [draw_pairs(space, c, 32, seed=1) for c in claims]
    verdicts = judge([tally((truth(a), truth(b)) for a, b in drawn) for drawn in pairs])
    assert [v.status for v in verdicts] == [CONFIRMED] * len(claims)
