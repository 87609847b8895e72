"""The two resolution protocols on one spec, paired: renders of the model's input
(``resolution = "model"``) against full frames of a fixed side that the model resizes and crops
itself (``resolution = 224``), on the same poses.

    .venv/bin/python benchmarks/resolution.py specs/quickstart.toml [--side 224] [--store DIR]

Runs the spec twice, changing only ``[render] resolution``, each into a store of its own under
``--store`` (default: a new folder in /tmp; an existing one resumes), one after the other. Then
pairs the results by object, environment and every parameter value, and prints each protocol's
accuracy, the discordant pairs (right only with one of them) and the exact two-sided McNemar
p-value (the ``mcnemar_p`` macro of ``sweep3d compare``): overall, per object and per value of
each parameter with at most eight values.
"""

from __future__ import annotations

import argparse
import tempfile
import tomllib
from pathlib import Path

import duckdb
import pandas as pd

import sweep3d
from sweep3d.results.compare import create_mcnemar


def variant(spec: Path, resolution: str | int, store: Path) -> sweep3d.Experiment:
    """``spec`` with only its resolution and its store changed (paths still relative to its folder)."""
    tables = tomllib.loads(spec.read_text(encoding="utf-8"))
    tables.setdefault("render", {})["resolution"] = resolution
    tables["experiment"]["store"] = str(store)
    return sweep3d.load(tables, base=spec.parent)


def paired(model: pd.DataFrame, fixed: pd.DataFrame, keys: list[str]) -> pd.DataFrame:
    """One row per configuration both protocols evaluated: ``correct_model``, ``correct_fixed``."""
    columns = [*keys, "correct"]
    pairs = model.loc[model.counted, columns].merge(fixed.loc[fixed.counted, columns], on=keys,
                                                    suffixes=("_model", "_fixed"), validate="one_to_one")
    return pairs


def table(pairs: pd.DataFrame, keys: list[str]) -> pd.DataFrame:
    """Accuracy of each protocol, discordant pairs and McNemar's p: overall and per level."""
    con = duckdb.connect()
    create_mcnemar(con)
    con.register("pairs", pairs)
    groups = ["'all'"] + [f"'{k} = ' || CAST(\"{k}\" AS VARCHAR)" for k in keys
                          if k != "environment" and pairs[k].nunique() <= 8]
    parts = [f"""SELECT {i} AS part, {g} AS "group", count(*) AS n,
                        round(100 * avg(correct_model::INT), 1) AS model_pct,
                        round(100 * avg(correct_fixed::INT), 1) AS fixed_pct,
                        count(*) FILTER (WHERE correct_model AND NOT correct_fixed) AS only_model,
                        count(*) FILTER (WHERE correct_fixed AND NOT correct_model) AS only_fixed
                 FROM pairs GROUP BY 2""" for i, g in enumerate(groups)]
    return con.execute(f"""SELECT * EXCLUDE (part), round(model_pct - fixed_pct, 1) AS points,
                                  mcnemar_p(only_model, only_fixed) AS p
                           FROM ({' UNION ALL BY NAME '.join(parts)}) ORDER BY part, "group" """).df()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("spec", type=Path)
    parser.add_argument("--side", type=int, default=224, help="the fixed side to compare with (default 224)")
    parser.add_argument("--store", type=Path, default=None, help="folder for the two stores (default: a new one in /tmp)")
    args = parser.parse_args()
    folder = args.store or Path(tempfile.mkdtemp(prefix="sweep3d-resolution-"))
    runs = {}
    for name, resolution in (("model", "model"), ("fixed", args.side)):
        experiment = variant(args.spec.resolve(), resolution, folder / f"store-{name}")
        experiment.run(progress=False)
        runs[name] = experiment
    keys = ["object", "environment", *runs["model"].spec.parameter_columns]
    pairs = paired(runs["model"].dataframe(), runs["fixed"].dataframe(), keys)
    print(f'{args.spec}: resolution = "model" against resolution = {args.side}, {len(pairs)} paired images '
          f"(stores under {folder})")
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(table(pairs, keys).to_string(index=False))


if __name__ == "__main__":
    main()
