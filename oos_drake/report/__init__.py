"""The report of an ``oos run``: one self-contained HTML page over the whole results folder.

The top floor of the package: it reads what the stages wrote (it imports the scenario data to
list the bodies and blocks, nothing imports it back). ``oos run`` writes ``OUT/report.html`` as
its last stage; ``oos report OUT`` writes it again for any results folder.

Quick tour::

    from oos_drake.report import load_run, headline_numbers, write_report

    results = load_run("out")                 # missing stages are None
    for h in headline_numbers(results):       # gamma, mu per subset, margins, P(fail) bound
        print(h.label, h.value, h.unit)
    write_report("out")                       # out/report.html
"""

from oos_drake.report.html import REPORT_FILE, render_report, write_report
from oos_drake.report.results import Headline, RunResults, headline_numbers, load_run

__all__ = [
    "REPORT_FILE",
    "Headline",
    "RunResults",
    "headline_numbers",
    "load_run",
    "render_report",
    "write_report",
]
