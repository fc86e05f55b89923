"""``oos report OUT_DIR``: (re)write the self-contained HTML report of an ``oos run`` folder."""

from __future__ import annotations

import argparse

from oos_drake.app.args import add_deprecated_alias, add_out_argument


def print_headlines(numbers, report_path=None, write=print) -> None:
    """Print the headline numbers (one a line, with unit and where) and the report's path.

    Parameters
    ----------
    numbers : list of oos_drake.report.results.Headline
    report_path : path-like, optional
    write : callable
        Where lines go.
    """
    from oos_drake.report.results import format_number

    write("[oos run] headline numbers:")
    for h in numbers:
        where = f"  ({h.where})" if h.where else ""
        write(f"  {h.label:70s} {format_number(h.value, h.unit):>12s}{where}")
    if report_path is not None:
        write(f"[oos run] report: {report_path}")


def _report(args: argparse.Namespace) -> int:
    from oos_drake.report.html import write_report
    from oos_drake.report.results import headline_numbers, load_run

    path = write_report(args.directory, args.campaign, args.out)
    print_headlines(headline_numbers(load_run(args.directory, args.campaign)), path)
    return 0


def register(subparsers) -> None:
    """Add ``oos report``."""
    parser = subparsers.add_parser(
        "report",
        help="self-contained HTML report of an oos run folder (OUT_DIR/report.html)",
        description=__doc__,
    )
    parser.add_argument("directory", metavar="OUT_DIR", help="results folder of oos run --out")
    parser.add_argument(
        "--campaign", default=None, help="campaign folder (default: the newest OUT_DIR/campaign-*)"
    )
    add_out_argument(
        parser, required=False, help="where to write the page (default: OUT_DIR/report.html)"
    )
    add_deprecated_alias(parser, "--output", "--out")
    parser.set_defaults(func=_report)
