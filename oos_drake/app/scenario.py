"""``oos model info`` (Delta block table) and ``oos model figures --out DIR`` (paper section 2).

Examples::

    oos model info                    # blocks of the mission LFR with occurrence counts
    oos model info --phase 7          # the docking-phase-7 LFR instead
    oos model figures --out figs      # sigma_moments, docking_sweeps, inertias, surface
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

from oos_drake.app.args import add_out_argument, add_scenario_argument

#: The models ``oos model info --phase`` builds: the mission's or a docking phase's.
PHASES = ("mission", "7", "8")


@dataclass(frozen=True, eq=False)
class ModelResult:
    """Outcome of the model stage (:func:`compute_model`): the scenario's LFR summarized;
    written by :func:`write_model` (``blocks.parquet``), printed by :meth:`lines` (what
    ``oos model info`` prints).

    Attributes
    ----------
    scenario : str
        Name of the scenario.
    phase : str
        ``"mission"`` or a docking phase (``"7"``, ``"8"``).
    title : str
        The model's input -> output description.
    nstates : int
        Number of states of the LFR.
    nz : int
        Number of Delta channels of the LFR.
    elapsed_s : float
        Wall time of the model build [s].
    blocks : pandas.DataFrame
        :func:`~oos_drake.scenario.model.delta_block_table` (for a tree: no paper groups, no
        ``paper_occurrences`` column).
    tree : bool
        The scenario is a schema-2 tree (its blocks named from its bodies).
    occurrences : int
        Total number of block occurrences.
    matches_paper : bool or None
        The occurrence counts equal the paper's (None: not checked, a tree or a docking phase).
    paper_delta : pandas.DataFrame or None
        :func:`~oos_drake.scenario.model.paper_delta_table` when ``matches_paper``.
    """

    scenario: str
    phase: str
    title: str
    nstates: int
    nz: int
    elapsed_s: float
    blocks: object
    tree: bool = False
    occurrences: int = 0
    matches_paper: bool | None = None
    paper_delta: object = None

    @property
    def status(self) -> int:
        """``oos model info``'s exit status: 1 when the occurrence counts differ from the
        paper's, else 0."""
        return 1 if self.matches_paper is False else 0

    def tables(self) -> dict:
        """The tables the stage writes: ``"blocks"`` (one row per block, its unit and range in
        columns; ``blocks.parquet``)."""
        return {"blocks": _blocks_table(self.blocks)}

    def lines(self) -> list[str]:
        """The report ``oos model info`` prints (without the written file's line)."""
        columns = ["name", "group", "kind", "nominal", "range", "occurrences", "paper_occurrences"]
        table = self.blocks[[c for c in columns if c in self.blocks.columns]]
        lines = [
            f"{self.title}; {self.nstates} states, {self.nz} Delta channels "
            f"(built in {self.elapsed_s:.2f} s)",
            table.to_string(index=False),
        ]
        if self.phase == "mission" and self.tree:
            lines.append(
                f"schema-2 tree {self.scenario}: blocks named from its bodies (docs/TREE.md)"
            )
        elif self.matches_paper is not None:
            if self.paper_delta is not None:
                lines.append("\npaper's Delta_P = diag(...) (section 2):")
                lines += [
                    f"  {row.sub_block:13s} {row.size:4d}  {row.content}"
                    for row in self.paper_delta.itertuples(index=False)
                ]
            lines.append(
                f"occurrence counts {'equal' if self.matches_paper else 'DIFFER FROM'} the "
                f"paper's (total {self.occurrences})"
            )
        return lines


def compute_model(scenario, phase: str = "mission") -> ModelResult:
    """Build the LFR of ``scenario`` (``oos model info``): the mission model or a docking
    phase's, its Delta blocks tabulated and, for the mission model of a schema-1 scenario,
    checked against the paper's occurrence counts. Prints and writes nothing.

    Parameters
    ----------
    scenario : Scenario
    phase : str
        ``"mission"``, ``"7"`` or ``"8"``.

    Returns
    -------
    ModelResult
    """
    from oos_drake.scenario.model import (
        PAPER_OCCURRENCES,
        build_docking_model,
        build_mission_model,
        delta_block_table,
        paper_delta_table,
    )
    from oos_drake.scenario.tree_scenario import is_tree

    if phase not in PHASES:
        raise ValueError(f"--phase must be one of {', '.join(PHASES)}, got {phase!r}")
    start = time.perf_counter()
    if phase == "mission":
        model = build_mission_model(scenario)
        title = "mission LFR: W_ext,G1 (6) -> xdd_G1 (6)"
    else:
        model = build_docking_model(phase, scenario)
        title = f"docking phase {phase} LFR: W_ext,G1 (6) -> xdd_G1 (6)"
    elapsed = time.perf_counter() - start
    table = delta_block_table(model)
    tree = is_tree(scenario)
    if tree:  # its blocks are named from its bodies: the paper's groups do not apply
        root = scenario.controlled_body
        title = f"mission LFR: [F; T] at G of {root} (6) -> [a; wdot] at G of {root} (6)"
        table["group"] = ""
        table = table.drop(columns="paper_occurrences")
    matches = paper = None
    if phase == "mission" and not tree:
        matches = model.occurrences == PAPER_OCCURRENCES
        paper = paper_delta_table(model) if matches else None
    return ModelResult(
        scenario=scenario.name,
        phase=phase,
        title=title,
        nstates=model.nstates,
        nz=model.nz,
        elapsed_s=elapsed,
        blocks=table,
        tree=tree,
        occurrences=sum(model.occurrences.values()),
        matches_paper=matches,
        paper_delta=paper,
    )


def write_model(result: ModelResult, folder) -> Path:
    """Write the model stage's block table ``blocks.parquet`` in ``folder`` (created,
    atomically); its path."""
    from oos_drake.files import atomic_write_bytes

    path = Path(folder) / "blocks.parquet"
    path.parent.mkdir(parents=True, exist_ok=True)
    table = result.tables()["blocks"]
    return atomic_write_bytes(path, lambda stream: table.to_parquet(stream, index=False))


@dataclass(frozen=True)
class FigureOptions:
    """Options of the model figures (``oos model figures``; ``oos run`` passes the defaults).

    Attributes
    ----------
    times : int
        Mission grid size (``--times``), at least 2.
    frequencies : int
        Frequency grid size, 0.01-100 Hz (``--frequencies``), at least 2.
    samples : int
        Uncertain samples per moment (``--samples``), at least 1.
    seed : int
        Sampling seed (``--seed``).
    """

    times: int = 330
    frequencies: int = 500
    samples: int = 20
    seed: int = 0

    def __post_init__(self):
        for option, value, least in (
            ("--times", self.times, 2),
            ("--frequencies", self.frequencies, 2),
            ("--samples", self.samples, 1),
        ):
            if not value >= least:
                raise ValueError(f"{option} {value}: must be at least {least}")


def write_model_figures(scenario, options: FigureOptions, folder):
    """Draw the paper's section-2 figures of ``scenario`` in ``folder``
    (:func:`oos_drake.scenario.figures.make_figures`: PNG and data file per figure).

    Returns
    -------
    FigureFiles
        Figure name -> (PNG, data file).

    Raises
    ------
    NotForTrees
        ``scenario`` is a schema-2 tree (the figures are the paper's topology).
    """
    from oos_drake.scenario.figures import make_figures
    from oos_drake.scenario.tree_scenario import NotForTrees, is_tree

    if is_tree(scenario):
        raise NotForTrees(
            f"scenario {scenario.name} is a schema-2 tree: the section-2 figures are the "
            "paper's topology (moments, docking sweeps, arm); not available for trees yet"
        )
    return make_figures(
        folder,
        scenario,
        n_times=options.times,
        n_frequencies=options.frequencies,
        n_samples=options.samples,
        seed=options.seed,
    )


def model(scenario, out, *, figures: FigureOptions | None = FigureOptions()) -> ModelResult:
    """The model stage of ``oos run``: :func:`compute_model` of the mission LFR, its report
    printed (as ``oos model info`` prints it), its block table written in ``out``
    (:func:`write_model`) and, unless ``figures`` is None, the section-2 figures drawn there
    (:func:`write_model_figures`, what ``oos model figures --out OUT`` draws).

    Returns
    -------
    ModelResult
        ``.status`` 1: the occurrence counts differ from the paper's (the block table written
        all the same, no figures: ``oos run`` stops there, as it did on ``oos model info``'s
        exit status).
    """
    result = compute_model(scenario)
    _print_model(result, write_model(result, out))
    if figures is not None and not result.status:  # a failed check stops oos run: no figures
        _print_figures(write_model_figures(scenario, figures, out))
    return result


def _print_figures(files) -> None:
    for name, (png, data) in files:
        print(f"{name:15s} {png}  {data}")


def _info(args: argparse.Namespace) -> int:
    from oos_drake.scenario.data import load_scenario

    result = compute_model(load_scenario(args.scenario), args.phase)
    _print_model(result, None if args.out is None else write_model(result, args.out))
    return result.status


def _print_model(result: ModelResult, written: Path | None) -> None:
    """Print the report of ``result``, the path of its block table (``written``) after the
    table."""
    lines = result.lines()
    if written is not None:
        lines.insert(2, f"block table: {written}")
    print("\n".join(lines))


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

    options = FigureOptions(args.times, args.frequencies, args.samples, args.seed)
    scenario = load_scenario(args.scenario)
    start = time.perf_counter()
    _print_figures(write_model_figures(scenario, options, args.out))
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
        choices=PHASES,
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
