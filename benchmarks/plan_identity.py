"""Keys unchanged: every spec in specs/ planned by two checkouts of sweep3d, compared byte for byte.

For each spec it dumps ``plan.rows()``, ``plan.table()`` (schema and rows) and every job
(index, scene, values, point, the four keys) as text; the two dumps must be identical.

    git -C . archive 5cb10c4 | tar -x -C /tmp/old
    .venv/bin/python benchmarks/plan_identity.py --old /tmp/old [--new .]
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

DUMP = """
import json, sys
from pathlib import Path
import sweep3d
from sweep3d.runner.pipeline import plan_spec
import sweep3d
root = Path(sys.argv[1]).resolve()
assert Path(sweep3d.__file__).resolve().is_relative_to(root), sweep3d.__file__
for spec in sorted(Path(sys.argv[2]).glob("*.toml")):
    plan = plan_spec(sweep3d.load(spec).spec)
    print(f"# {spec.name} {len(plan.jobs)} in frame, {len(plan.out_of_frame)} out")
    for row in plan.rows():
        print(json.dumps(row, ensure_ascii=False))
    table = plan.table()
    print(repr(table.schema))
    print(json.dumps(table.to_pylist(), ensure_ascii=False, default=str))
    for j in list(plan.jobs) + list(plan.out_of_frame):
        print(json.dumps([j.index, j.scene, j.values, repr(j.point), j.render_key, j.image_key, j.pred_key,
                          j.parts_key]))
"""


def dump(checkout: Path, specs: Path) -> str:
    """Every spec's plan as text, made by the sweep3d of ``checkout`` (first on PYTHONPATH)."""
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    out = subprocess.run([sys.executable, "-c", DUMP, str(checkout), str(specs)], env=env, cwd=checkout, capture_output=True,
                         text=True)
    if out.returncode:
        sys.exit(f"planning with {checkout} failed:\n{out.stderr[-3000:]}")
    return out.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, required=True, help="the checkout to compare against")
    parser.add_argument("--new", type=Path, default=REPO, help="the checkout under test (default: this one)")
    args = parser.parse_args()
    specs = args.new.resolve() / "specs"
    texts = {name: dump(path.resolve(), specs) for name, path in (("old", args.old), ("new", args.new))}
    for name, text in texts.items():
        print(f"{name}: {len(text.splitlines())} lines, sha256 {hashlib.sha256(text.encode()).hexdigest()}")
    print("\n".join(line for line in texts["new"].splitlines() if line.startswith("# ")))
    if texts["old"] != texts["new"]:
        sys.exit("the plans differ")
    print("identical")


if __name__ == "__main__":
    main()
