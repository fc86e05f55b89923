"""One argument helper for every ``oos`` command: one name and one help text per option.

``--out`` (where results go: :func:`add_out_argument`), ``--workers`` (parallel worker processes
or threads) and ``--scheduler`` (where they run: local processes or Dask,
:func:`add_parallel_arguments`), ``--quiet`` (no progress bars: :func:`add_quiet_argument`),
``--f-min``/``--f-max`` (frequency range [Hz]: :func:`add_frequency_range`), ``--scenario`` (the
scenario data file: :func:`add_scenario_argument`; the only place where the paper's scenario is
the default), ``--sampled``/``--delay`` (the loop model: :func:`add_loop_arguments`). Older
spellings (``--jobs``, ``--no-progress``, ``--fmin``, ``--fmax``) are hidden aliases that raise a
``DeprecationWarning`` (:func:`add_deprecated_alias`).

Errors that a user can fix (bad data, bad spec, unknown names) are ``ValueError``s (or
``FileNotFoundError``/``KeyError``): :func:`run_command` prints them as one line and returns exit
status 2.
"""

from __future__ import annotations

import argparse
import sys
import warnings


class _DeprecatedAlias(argparse.Action):
    """Hidden old spelling of an option: stores into the new option's ``dest``.

    It warns with a :class:`DeprecationWarning` (silent by default, so scripts that check the
    command's stderr keep working).
    """

    def __init__(self, option_strings, dest, new: str, **kwargs):
        self.new = new
        super().__init__(option_strings, dest, help=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        warnings.warn(f"{option_string} is deprecated, use {self.new}", DeprecationWarning, 2)
        setattr(namespace, self.dest, self.const if self.nargs == 0 else values)


def add_deprecated_alias(
    parser: argparse.ArgumentParser, old: str, new: str, *, flag: bool = False, type=None
) -> None:
    """Accept ``old`` as a hidden, deprecated spelling of option ``new`` of ``parser``.

    Parameters
    ----------
    old, new : str
        Option strings (``"--jobs"``, ``"--workers"``); ``new`` must already be defined.
    flag : bool
        ``new`` is a ``store_true`` flag (``--no-progress`` -> ``--quiet``).
    type : callable, optional
        Conversion of the value (as for ``new``).
    """
    dest = new.lstrip("-").replace("-", "_")
    options = {"nargs": 0, "const": True} if flag else {"type": type}
    parser.add_argument(
        old, dest=dest, new=new, action=_DeprecatedAlias, default=argparse.SUPPRESS, **options
    )


def add_loop_arguments(parser) -> None:
    """``--sampled`` / ``--delay``: the loop model, shared by ``oos synth`` and ``oos analyze``."""
    parser.add_argument(
        "--sampled",
        action="store_true",
        help="model the flight software's sample-and-hold (rate: the scenario's [control] "
        "flight_software_rate_hz) as a rational approximation inside the loop "
        "(default: the continuous loop)",
    )
    parser.add_argument(
        "--delay",
        type=float,
        default=None,
        help="computation delay of the sampled loop [s] (default: DesignSpecification."
        "computation_delay_s, 0: the flight software writes the torque at the sample instant)",
    )


def loop_specification(spec, args):
    """``spec`` (a ``DesignSpecification``) with the loop model of ``--sampled`` / ``--delay``.

    Raises
    ------
    ValueError
        ``--delay`` without ``--sampled``, or a negative delay.
    """
    import dataclasses

    if args.delay is not None and not args.sampled:
        raise ValueError("--delay needs --sampled (the continuous loop has no computation delay)")
    delay = spec.computation_delay_s if args.delay is None else float(args.delay)
    return dataclasses.replace(spec, sampled=bool(args.sampled), computation_delay_s=delay)


def add_parallel_arguments(
    parser: argparse.ArgumentParser, *, workers: int = 2, help: str = "worker processes"
) -> None:
    """Add ``--workers N`` and ``--scheduler`` (one name and help text for every command with
    parallel work): ``processes`` (default), ``dask``/``local`` or a Dask scheduler address; the
    values go to :func:`oos_drake.processes.make_executor`. ``workers``: the default of
    ``--workers``; ``help``: its help text (what runs in parallel)."""
    from oos_drake.processes import SCHEDULER_HELP, check_scheduler

    def scheduler(value: str) -> str:
        try:
            return check_scheduler(value)
        except ValueError as exc:  # argparse: usage line, this message, exit status 2
            raise argparse.ArgumentTypeError(str(exc)) from None

    parser.add_argument("--workers", type=int, default=workers, help=help)
    parser.add_argument(
        "--scheduler", default=None, type=scheduler, metavar="SCHEDULER", help=SCHEDULER_HELP
    )


SCENARIO_HELP = (
    "scenario data file (TOML: spacecraft, mission and [control] requirements) or the name of a "
    "shipped one (paper, heavy_target, flexible_satellite, geo_satellite, servicer_7dof); "
    "default: {default}"
)


def add_scenario_argument(parser: argparse.ArgumentParser, *, default: str = "the paper's") -> None:
    """Add ``--scenario FILE`` (one name and help text for every command that builds a model).

    The value stays a string (``None``: the command's default, ``default`` in the help: the
    paper's scenario, or the one an analysis folder records) for
    :func:`oos_drake.scenario.data.load_scenario`, which resolves shipped names.
    """
    parser.add_argument(
        "--scenario", default=None, metavar="FILE", help=SCENARIO_HELP.format(default=default)
    )


def add_out_argument(
    parser: argparse.ArgumentParser,
    *,
    required: bool = True,
    default=None,
    type=None,
    help: str = "output directory",
) -> None:
    """Add ``--out`` (where the command writes; one name for every command)."""
    if required:
        parser.add_argument("--out", required=True, type=type, help=help)
    else:
        parser.add_argument("--out", default=default, type=type, help=help)


def add_quiet_argument(parser: argparse.ArgumentParser, *, old: bool = False) -> None:
    """Add ``--quiet`` (no progress bars); ``old``: also the deprecated ``--no-progress``."""
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    if old:
        add_deprecated_alias(parser, "--no-progress", "--quiet", flag=True)


def add_frequency_range(
    parser: argparse.ArgumentParser, f_min: float, f_max: float, *, what: str = "grid frequency"
) -> None:
    """Add ``--f-min``/``--f-max`` [Hz] with defaults ``f_min``, ``f_max``."""
    parser.add_argument("--f-min", type=float, default=f_min, help=f"lowest {what} [Hz]")
    parser.add_argument("--f-max", type=float, default=f_max, help=f"highest {what} [Hz]")


def run_command(args: argparse.Namespace) -> int:
    """Run the parsed command ``args.func(args)``; its exit status. A user-fixable error
    (``ValueError``, ``FileNotFoundError``, ``KeyError``) is printed as one line: status 2."""
    try:
        status = args.func(args)
    except (ValueError, FileNotFoundError, KeyError) as exc:
        message = exc.args[0] if exc.args else exc
        print(f"oos {args.command}: error: {message}", file=sys.stderr)
        return 2
    return int(status or 0)
