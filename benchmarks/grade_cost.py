"""What grading every finding costs against the cold run that found them, in one sitting.

Each round makes a fresh store for the quickstart (the spec with only its store changed), then
times, from process start to exit (``/usr/bin/time``'s wall and user + system CPU): a cold
``sweep3d run --no-report``; ``sweep3d grade`` at each ``--budgets`` (``default``: the command's
own, twice the run's renders), each on a copy of the store the run left; and the default grade
again over its own store (everything cached). It prints each command's time, its ratio to the
round's run, the grades it gave and the renders it made, and the load average before and after.

    .venv/bin/python benchmarks/grade_cost.py [--rounds 2] [--budgets default,240]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def timed(args: list[str], cwd: Path) -> tuple[float, float, str]:
    """(wall s, CPU s, output) of ``python -m sweep3d args`` from process start to exit."""
    out = subprocess.run(["/usr/bin/time", "-f", "TIME %e %U %S", sys.executable, "-m", "sweep3d", *args],
                         cwd=cwd, capture_output=True, text=True, env={**os.environ, "COLUMNS": "200"})
    if out.returncode != 0:
        sys.exit(f"sweep3d {' '.join(args)} failed:\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}")
    wall, user, system = re.findall(r"TIME ([\d.]+) ([\d.]+) ([\d.]+)", out.stderr)[-1]
    return float(wall), float(user) + float(system), out.stdout + out.stderr


def spec_in(folder: Path) -> Path:
    text = (REPO / "specs" / "quickstart.toml").read_text()
    text = re.sub(r'(?m)^store\s*=.*$', f'store = "{folder / ".sweep3d"}"', text)
    path = folder / "quickstart.toml"
    path.write_text(text)
    return path


def summary(output: str) -> str:
    """The grade's counts and its renders, from what it printed."""
    grades = re.search(r"grades: (.*)", output)
    renders = re.search(r"(\d+) renders of the budget's (\d+) used \((\d+) rendered now\)", output)
    found = grades.group(1) if grades else "?"
    return found + (f"; {renders.group(1)} of {renders.group(2)} used, {renders.group(3)} rendered" if renders else "")


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--budgets", default="default")
    args = parser.parse_args()
    budgets = [b.strip() for b in args.budgets.split(",") if b.strip()]
    print("| round | command | wall s | CPU s | × the run | grades; renders | load before → after |")
    print("|---|---|---:|---:|---:|---|---|")
    for round_ in range(args.rounds):
        root = Path(tempfile.mkdtemp(prefix="grade-cost-"))
        run_folder = root / "run"
        run_folder.mkdir()
        spec = spec_in(run_folder)
        before = load()
        wall, cpu, _ = timed(["run", str(spec), "--no-report"], run_folder)
        run_wall = wall
        print(f"| {round_} | cold `run --no-report` | {wall:.1f} | {cpu:.1f} | 1.00 | – | {before} → {load()} |",
              flush=True)
        for budget in budgets:
            folder = root / f"grade-{budget}"
            shutil.copytree(run_folder, folder, symlinks=True)
            graded = spec_in(folder)
            extra = [] if budget == "default" else ["--budget", budget]
            for again in (False, True) if budget == "default" else (False,):
                before = load()
                wall, cpu, output = timed(["grade", str(graded), *extra], folder)
                name = f"`grade`{' ' + ' '.join(extra) if extra else ''}{' again' if again else ''}"
                print(f"| {round_} | {name} | {wall:.1f} | {cpu:.1f} | {wall / run_wall:.2f} | {summary(output)} | "
                      f"{before} → {load()} |", flush=True)
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
