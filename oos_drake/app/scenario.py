"""``oos model info`` (Delta block table) and ``oos model figures --out DIR`` (paper section 2).

Examples::

    oos model info                    # blocks of the mission LFR with occurrence counts
    oos model info --phase 7          # the docking-phase-7 LFR instead
    oos model figures --out figs      # sigma_moments, docking_sweeps, inertias, surface
"""

from __future__ import annotations

import argparse
import time

from oos_drake.app.args import add_out_argument, add_scenario_argument


def _info(args: argparse.Namespace) -> int:
    from oos_drake.scenario.data import load_scenario
    from oos_drake.scenario.model import (
        PAPER_OCCURRENCES,
        build_docking_model,
        build_mission_model,
        delta_block_table,
    )

    scenario = load_scenario(args.scenario)
    start = time.perf_counter()
    if args.phase == "mission":
        model = build_mission_model(scenario)
        title = "mission LFR: W_ext,G1 (6) -> xdd_G1 (6)"
    else:
        model = build_docking_model(args.phase, scenario)
        title = f"docking phase {args.phase} LFR: W_ext,G1 (6) -> xdd_G1 (6)"
    elapsed = time.perf_counter() - start
    table = delta_block_table(model)
    from oos_drake.scenario.tree_scenario import is_tree

    if is_tree(scenario):  # its blocks are named from its bodies: the paper's groups do not apply
        root = scenario.controlled_body
        title = f"mission LFR: [F; T] at G of {root} (6) -> [a; wdot] at G of {root} (6)"
        table["group"] = ""
        table = table.drop(columns="paper_occurrences")
    print(f"{title}; {model.nstates} states, {model.nz} Delta channels (built in {elapsed:.2f} s)")
    columns = ["name", "group", "kind", "nominal", "range", "occurrences", "paper_occurrences"]
    print(table[[c for c in columns if c in table.columns]].to_string(index=False))
    if args.out is not None:
        from pathlib import Path

        path = Path(args.out) / "blocks.parquet"
        path.parent.mkdir(parents=True, exist_ok=True)
        _blocks_table(table).to_parquet(path, index=False)
        print(f"block table: {path}")
    if args.phase == "mission" and is_tree(scenario):  # the blocks are named from its bodies
        print(f"schema-2 tree {scenario.name}: blocks named from its bodies (docs/TREE.md)")
        return 0
    if args.phase == "mission":
        from oos_drake.scenario.model import paper_delta_table

        matches = model.occurrences == PAPER_OCCURRENCES
        if matches:
            print("\npaper's Delta_P = diag(...) (section 2):")
            for row in paper_delta_table(model).itertuples(index=False):
                print(f"  {row.sub_block:13s} {row.size:4d}  {row.content}")
        print(
            f"occurrence counts {'equal' if matches else 'DIFFER FROM'} the paper's "
            f"(total {sum(model.occurrences.values())})"
        )
        return 0 if matches else 1
    return 0


def _blocks_table(table):
    """The block table as stored: one row per block, its unit and range in columns."""
    import pandas as pd

    low, high = zip(
        *(r if r is not None else (float("nan"),) * 2 for r in table["range"]), strict=True
    )
    return pd.DataFrame(
        {
            "block": table["name"],
            "kind": table["kind"],
            "quantity": table["quantity"],
            "unit": [u or "-" for u in table["unit"]],
            "nominal [unit]": table["nominal"].astype(float),
            "lower [unit]": low,
            "upper [unit]": high,
            "occurrences": table["occurrences"],
            "group": table["group"],
        }
    )


def _figures(args: argparse.Namespace) -> int:
    from oos_drake.scenario.data import load_scenario
    from oos_drake.scenario.figures import make_figures
    from oos_drake.scenario.tree_scenario import NotForTrees, is_tree

    scenario = load_scenario(args.scenario)
    if is_tree(scenario):
        raise NotForTrees(
            f"scenario {scenario.name} is a schema-2 tree: the section-2 figures are the "
            "paper's topology (moments, docking sweeps, arm); not available for trees yet"
        )
    start = time.perf_counter()
    files = make_figures(
        args.out,
        scenario,
        n_times=args.times,
        n_frequencies=args.frequencies,
        n_samples=args.samples,
        seed=args.seed,
    )
    for name, (png, data) in files:
        print(f"{name:15s} {png}  {data}")
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0


def register(subparsers) -> None:
    """Add ``oos model info`` and ``oos model figures``."""
    parser = subparsers.add_parser("model", help="the TITOP LFR of the scenario: info and figures")
    commands = parser.add_subparsers(dest="model_command", metavar="SUBCOMMAND")
    parser.set_defaults(func=lambda args: (parser.print_help(), 1)[1])

    info = commands.add_parser("info", help="Delta block table with occurrence counts")
    info.add_argument(
        "--phase",
        choices=("mission", "7", "8"),
        default="mission",
        help="mission model (default) or a docking-phase model",
    )
    add_out_argument(info, required=False, help="also write the block table as OUT/blocks.parquet")
    add_scenario_argument(info)
    info.set_defaults(func=_info)

    figures = commands.add_parser("figures", help="paper section-2 figures (PNG) and their data")
    add_out_argument(figures)
    figures.add_argument("--times", type=int, default=330, help="mission grid size (default 330)")
    figures.add_argument(
        "--frequencies",
        type=int,
        default=500,
        help="frequency grid size, 0.01-100 Hz (default 500)",
    )
    figures.add_argument(
        "--samples", type=int, default=20, help="uncertain samples per moment (default 20)"
    )
    figures.add_argument("--seed", type=int, default=0, help="sampling seed")
    add_scenario_argument(figures)
    figures.set_defaults(func=_figures)
