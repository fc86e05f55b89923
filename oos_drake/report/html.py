"""One self-contained HTML page of an ``oos run``: every figure embedded, no network needed.

:func:`render_report` turns a :class:`~oos_drake.report.results.RunResults` into the page;
:func:`write_report` writes it (atomically) as ``OUT/report.html``. The figures are the PNG files
the stages wrote, embedded as base64 ``data:`` URIs; the page carries a Content-Security-Policy
that forbids any load from the network (a figure that is not embedded would not show, and a
browser says so on its console); the page has no script. A stage that did not run, or a table
that is not there, is shown as "not run" rather than failing the report.

Every number is shown with its unit: table columns carry it in their name (``name [unit]``,
the package's convention) and single numbers after the value (``[-]`` when dimensionless).
The headline numbers carry ``data-headline`` (their key) and ``data-value`` (the value at full
precision) attributes, so that a test can read them from the page.
"""

from __future__ import annotations

import base64
import datetime
import hashlib
import html
import importlib.metadata
import math
import os
import platform
from pathlib import Path

import pandas as pd

from oos_drake.files import atomic_write_bytes
from oos_drake.report.results import (
    ANY_FAILURE,
    STAGES,
    Headline,
    RunResults,
    format_number,
    headline_numbers,
)

#: File name of the report in the results folder.
REPORT_FILE = "report.html"
#: Reference classical margins of the mission's loops (ECSS-E-ST-60-10C's usual values; the
#: scenario's ``[control]`` states no margin requirement): column -> (threshold, unit).
REFERENCE_MARGINS = {
    "gain margin upper [dB]": (6.0, "dB"),
    "phase margin [deg]": (30.0, "deg"),
}
#: Units of the ``[control]`` requirements (``ControlRequirements`` fields).
REQUIREMENT_UNITS = {
    "pointing_requirement": "rad",
    "torque_limit": "N m",
    "flight_software_rate_hz": "Hz",
    "star_tracker_cutoff_hz": "Hz",
    "gyro_cutoff_hz": "Hz",
    "star_tracker_noise": "rad",
    "gyro_noise": "rad/s",
    "wheel_frequency_hz": "Hz",
    "wheel_damping": "-",
    "rolloff_order": "-",
    "rolloff_cutoff_hz": "Hz",
    "disturbance_gains": "N m",
    "disturbance_denominator": "s, -",
    "additive_weight_db": "dB",
    "multiplicative_diagonal": "-",
    "multiplicative_off_diagonal": "-",
}
#: Widest figure shown at half the page's width [px].
NARROW_FIGURE = 1000
#: Packages whose versions the report lists.
VERSIONED_PACKAGES = ("oos_drake", "numpy", "scipy", "pandas", "pyarrow", "drake", "control")

#: Content-Security-Policy of the page: nothing from the network; figures as data URIs; inline
#: style and scripts only (the page has none, a test's probe adds one).
_CSP = (
    "default-src 'none'; img-src data:; style-src 'unsafe-inline'; script-src 'unsafe-inline'; "
    "base-uri 'none'; form-action 'none'"
)

_STYLE = """
body { font-family: system-ui, -apple-system, 'Segoe UI', sans-serif; margin: 0; color: #1d232a;
       background: #f6f7f9; line-height: 1.4; }
header { background: #1f3a5f; color: white; padding: 18px 32px; }
header h1 { margin: 0 0 4px 0; font-size: 24px; }
header p { margin: 2px 0; opacity: 0.9; font-size: 14px; }
nav { background: #e4e9f0; padding: 8px 32px; font-size: 14px; }
nav a { margin-right: 14px; color: #1f3a5f; }
main { padding: 8px 32px 40px 32px; max-width: 1500px; }
section { background: white; border-radius: 6px; padding: 8px 20px 16px 20px; margin: 16px 0;
          box-shadow: 0 1px 3px rgba(0,0,0,0.12); }
h2 { color: #1f3a5f; border-bottom: 2px solid #e4e9f0; padding-bottom: 4px; }
h3 { color: #33475b; margin-bottom: 6px; }
table { border-collapse: collapse; font-size: 13px; margin: 6px 0 12px 0; }
th, td { border: 1px solid #d5dbe3; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #eef2f7; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
.scroll { overflow-x: auto; }
.badge { display: inline-block; padding: 2px 10px; border-radius: 12px; font-size: 13px;
         font-weight: 600; margin: 2px 6px 2px 0; }
.pass { background: #d8f3dc; color: #1b5e20; border: 1px solid #7cc68a; }
.fail { background: #fde2e1; color: #8e1b14; border: 1px solid #ee8d86; }
.na { background: #eceff1; color: #55606b; border: 1px solid #c5cbd1; }
.notrun { color: #8a5a00; background: #fff4d6; padding: 6px 10px; border-radius: 4px; }
.figures { display: flex; flex-wrap: wrap; gap: 12px; align-items: flex-start; }
figure { margin: 6px 0 12px 0; max-width: 100%; }
figure.narrow { max-width: calc(50% - 8px); }
figure .frame { max-height: 950px; overflow: auto; border: 1px solid #d5dbe3; }
figure img { max-width: 100%; display: block; background: white; }
figcaption { font-size: 13px; color: #55606b; }
pre { background: #f3f5f8; padding: 10px; font-size: 12px; overflow-x: auto; }
table.headlines td, table.headlines th { font-size: 14px; padding: 5px 10px; }
"""

# -- small HTML helpers ---------------------------------------------------------------------------


def _e(text) -> str:
    return html.escape(str(text))


def not_run(what: str) -> str:
    """The placeholder of a missing stage or table."""
    return f'<p class="notrun">not run: {_e(what)}</p>'


def badge(label: str, met: bool | None) -> str:
    """A requirement badge: met (green), not met (red) or not checked (grey)."""
    css, word = {True: ("pass", "met"), False: ("fail", "NOT met"), None: ("na", "not checked")}[
        met
    ]
    return f'<span class="badge {css}" data-met="{_e(met)}">{_e(label)}: {word}</span>'


def _cell(value, digits: int = 4) -> str:
    if isinstance(value, bool) or value is None:
        return f"<td>{_e(value)}</td>"
    if isinstance(value, int | float) and not isinstance(value, bool):
        number = float(value)
        text = "n/a" if math.isnan(number) else f"{number:.{digits}g}"
        return f'<td class="num">{text}</td>'
    if hasattr(value, "dtype") and getattr(value.dtype, "kind", "") in "iuf":
        return _cell(float(value), digits)
    return f"<td>{_e(value)}</td>"


def table_html(table: pd.DataFrame | None, columns=None, *, what: str = "", digits: int = 4) -> str:
    """A DataFrame as an HTML table (numbers to ``digits`` significant digits; their units are in
    the column names); the "not run" placeholder when ``table`` is None."""
    if table is None:
        return not_run(what)
    if columns is not None:
        table = table[[c for c in columns if c in table.columns]]
    if table.empty:
        return f"<p>{_e(what)}: no rows</p>"
    head = "".join(f"<th>{_e(c)}</th>" for c in table.columns)
    body = "".join(
        "<tr>" + "".join(_cell(v, digits) for v in row) + "</tr>"
        for row in table.itertuples(index=False)
    )
    return f'<div class="scroll"><table><tr>{head}</tr>{body}</table></div>'


def rows_html(rows: list[tuple[str, str]]) -> str:
    """A two-column table of (name, formatted value)."""
    body = "".join(f"<tr><th>{_e(k)}</th><td>{v}</td></tr>" for k, v in rows)
    return f"<table>{body}</table>"


def _png_width(content: bytes) -> int:
    """Width of a PNG [px] (its IHDR chunk; 0 when ``content`` is not a PNG)."""
    if content[:8] != b"\x89PNG\r\n\x1a\n" or len(content) < 24:
        return 0
    return int.from_bytes(content[16:20], "big")


def figure_html(path: Path, caption: str = "") -> str:
    """``path`` (a PNG) embedded as a base64 data URI, with a caption; a narrow figure (at most
    :data:`NARROW_FIGURE` pixels wide) takes half the width, so two go side by side."""
    content = Path(path).read_bytes()
    data = base64.b64encode(content).decode("ascii")
    caption = caption or Path(path).name
    narrow = 0 < _png_width(content) <= NARROW_FIGURE
    opening = '<figure class="narrow">' if narrow else "<figure>"
    return (
        f'{opening}<div class="frame"><img alt="{_e(Path(path).name)}" '
        f'src="data:image/png;base64,{data}"></div>'
        f"<figcaption>{_e(caption)}</figcaption></figure>"
    )


def figures_html(paths: list[Path], what: str) -> str:
    """Every figure of ``paths`` (side by side where they fit; a very tall one scrolls in its
    frame), or the "not run" placeholder."""
    if not paths:
        return not_run(what)
    return '<div class="figures">' + "".join(figure_html(p) for p in paths) + "</div>"


def _value(value, unit: str) -> str:
    return _e(format_number(value, unit))


# -- sections -------------------------------------------------------------------------------------


def headlines_html(numbers: list[Headline]) -> str:
    """The headline table; each value cell carries ``data-headline`` and ``data-value``."""
    if not numbers:
        return not_run("no stage results to summarize")
    rows = "".join(
        f"<tr><th>{_e(h.label)}</th>"
        f'<td class="num" data-headline="{_e(h.key)}" data-value="{h.value!r}">'
        f"{_e(format_number(h.value, h.unit))}</td><td>{_e(h.where)}</td>"
        f"<td><small>{_e(h.source)}</small></td></tr>"
        for h in numbers
    )
    return (
        '<table class="headlines"><tr><th>headline</th><th>value</th><th>where</th>'
        f"<th>read from</th></tr>{rows}</table>"
    )


def _load_scenario(results: RunResults):
    """The run's scenario (None when its file is gone or invalid) and why not."""
    from oos_drake.scenario.data import load_scenario

    path = results.scenario_file
    if path is None:
        return None, "no scenario recorded (timings.json, analysis and controller missing)"
    if not path.is_file():
        return None, f"scenario file {path} not found"
    try:
        return load_scenario(path), ""
    except ValueError as error:
        return None, f"scenario file {path}: {error}"


def _bodies_table(scenario) -> pd.DataFrame:
    from oos_drake.scenario.tree_scenario import is_tree

    if is_tree(scenario):
        return scenario.bodies_table()
    rows = []
    for hub in scenario.hubs.values():
        jxx, jyy, jzz = (float(x) for x in hub.inertia.diagonal())
        rows.append(
            {
                "body": hub.name,
                "kind": "rigid hub",
                "description": hub.description,
                "mass [kg]": hub.mass,
                "Jxx [kg m^2]": jxx,
                "Jyy [kg m^2]": jyy,
                "Jzz [kg m^2]": jzz,
                "mass uncertainty [%]": hub.mass_uncertainty_percent,
                "first mode [Hz]": math.nan,
            }
        )
    for array in scenario.arrays.values():
        model = array.model
        jxx, jyy, jzz = (float(x) for x in model.inertia.diagonal())
        rows.append(
            {
                "body": array.name,
                "kind": f"flexible array on {array.parent} ({model.n_modes} modes)",
                "description": model.description,
                "mass [kg]": model.mass,
                "Jxx [kg m^2]": jxx,
                "Jyy [kg m^2]": jyy,
                "Jzz [kg m^2]": jzz,
                "mass uncertainty [%]": math.nan,
                "first mode [Hz]": float(model.frequencies_hz[0]),
            }
        )
    rows.append(
        {
            "body": "arm",
            "kind": f"robotic arm on {scenario.arm.parent} ({len(scenario.arm.links)} links)",
            "description": "",
            "mass [kg]": scenario.arm.total_mass,
            "Jxx [kg m^2]": math.nan,
            "Jyy [kg m^2]": math.nan,
            "Jzz [kg m^2]": math.nan,
            "mass uncertainty [%]": math.nan,
            "first mode [Hz]": math.nan,
        }
    )
    return pd.DataFrame(rows)


def _parameters_table(scenario) -> pd.DataFrame:
    """The uncertain blocks of the scenario's mission LFR: nominal, range, unit."""
    from oos_drake.scenario.model import build_mission_model

    blocks = build_mission_model(scenario).blocks
    rows = []
    for row in blocks.itertuples(index=False):
        low, high = row.range if row.range is not None else (math.nan, math.nan)
        rows.append(
            {
                "block": row.name,
                "kind": row.kind,
                "quantity": row.quantity,
                "unit": row.unit or "-",
                "nominal [unit]": row.nominal,
                "lower [unit]": low,
                "upper [unit]": high,
                "repetitions": row.repetitions,
            }
        )
    return pd.DataFrame(rows)


def scenario_section(results: RunResults) -> str:
    """Bodies, uncertain parameters and the ``[control]`` requirements of the run's scenario."""
    scenario, why = _load_scenario(results)
    if scenario is None:
        return not_run(why)
    parts = [
        f"<p><b>{_e(scenario.name)}</b>: {_e(scenario.description)}<br>"
        f"file <code>{_e(scenario.source)}</code></p>",
        "<h3>Bodies</h3>",
        table_html(_bodies_table(scenario)),
        "<h3>Uncertain parameters (mission LFR blocks)</h3>",
    ]
    if results.blocks is not None:
        parts.append(table_html(results.blocks))
    else:  # an older results folder: build the LFR (seconds)
        try:
            parts.append(table_html(_parameters_table(scenario)))
        except Exception as error:  # noqa: BLE001 - the report must not fail on a model error
            parts.append(not_run(f"mission LFR could not be built ({error})"))
    control = scenario.control
    rows = []
    for name, unit in REQUIREMENT_UNITS.items():
        value = getattr(control, name, None)
        if value is None:
            continue
        shown = (
            ", ".join(f"{v:.4g}" for v in value) + f" [{unit}]"
            if isinstance(value, tuple | list)
            else format_number(value, unit)
        )
        rows.append((name, _e(shown)))
    parts += ["<h3>Requirements and design data (<code>[control]</code>)</h3>", rows_html(rows)]
    parts += ["<h3>Model figures</h3>", figures_html(results.figures("model"), "model figures")]
    return "".join(parts)


def _gain_table(record: dict, key: str, unit: str) -> str:
    value = (record.get(key) or {}).get("value")
    if value is None:
        return not_run(key)
    frame = pd.DataFrame(value, columns=[f"{key} {a} [{unit}]" for a in ("x", "y", "z")])
    frame.insert(0, "torque axis", ["x", "y", "z"][: len(frame)])
    return table_html(frame)


def controller_section(results: RunResults, numbers: list[Headline]) -> str:
    """Structure, gains, gamma and the requirement badges."""
    record = results.controller
    if record is None:
        return not_run("controller stage (controller/controller.json)")
    control = record.get("controller", {})
    rolloff = control.get("rolloff", {})
    badges = [
        badge(
            "H-infinity performance (pointing and torque weights): gamma < 1",
            record.get("requirement_met"),
        )
    ]
    by_key = {h.key: h for h in numbers}
    mu_total = by_key.get("mu_total")
    badges.append(
        badge(
            "robust stability over Delta_tot: peak of mu < 1",
            None if mu_total is None else bool(mu_total.value < 1.0),
        )
    )
    margins = results.margins
    for column, (threshold, unit) in REFERENCE_MARGINS.items():
        met = None
        if margins is not None and column in margins.columns:
            met = bool(margins[column].min() >= threshold)
        badges.append(badge(f"{column.split(' [')[0]} >= {threshold:g} {unit} (reference)", met))
    summary = results.campaign_summary
    if summary is not None and "violations" in summary.columns:
        for row in summary.itertuples(index=False):
            requirement = getattr(row, "requirement", "")
            if not requirement or row.metric == ANY_FAILURE:
                continue
            violations = getattr(row, "violations", math.nan)
            met = None if pd.isna(violations) else bool(int(violations) == 0)
            badges.append(badge(f"campaign: {row.metric} {requirement}", met))
    rows = [
        ("structure", _e(control.get("structure", ""))),
        ("gamma", _value(record.get("gamma"), "-")),
        ("gamma of the baseline (start)", _value(record.get("gamma_baseline"), "-")),
        (
            "roll-off",
            _e(
                f"{rolloff.get('type', '?')}, order {rolloff.get('order', '?')} [-], cut-off "
                f"{format_number(rolloff.get('cutoff_hz'), 'Hz')}"
            ),
        ),
        ("model source", _e(record.get("model_source", ""))),
        ("wall time of the synthesis", _value(record.get("wall_time_s"), "s")),
    ]
    return "".join(
        [
            '<div class="badges">' + "".join(badges) + "</div>",
            rows_html(rows),
            "<h3>Proportional gains K_p</h3>",
            _gain_table(control, "K_p", "N m/rad"),
            "<h3>Derivative gains K_d</h3>",
            _gain_table(control, "K_d", "N m s/rad"),
        ]
    )


def _physical_column(results: RunResults) -> pd.Series | None:
    """Per (study, subset): is the destabilizing perturbation a physical body? From the
    confirmation's largest physical scale: physical when ``1 / mu lower <= alpha physical max``."""
    table = results.confirmation
    needed = {"study", "subset", "mu lower [-]", "alpha physical max [-]"}
    if table is None or not needed <= set(table.columns):
        return None
    alpha = 1.0 / table["mu lower [-]"].astype(float)
    physical = alpha <= table["alpha physical max [-]"].astype(float)
    return pd.Series(
        physical.to_numpy(), index=pd.MultiIndex.from_frame(table[["study", "subset"]])
    )


def analysis_section(results: RunResults) -> str:
    """Guaranteed peaks per subset, the mu figures, the worst cases in physical units."""
    peaks = results.peaks
    parts = ["<h3>Peak of mu per study and subset</h3>"]
    if peaks is None:
        parts.append(not_run("analysis stage (analysis/stability_peaks.parquet)"))
    else:
        location = [c for c in ("time [s]", "stiffness [N/m or N m/rad]") if c in peaks.columns]
        parts.append(
            "<p>The guaranteed peak is proved on the whole frequency axis at every analyzed "
            "configuration; the interval [lower, upper] is the certified one at the critical "
            "configuration and frequency.</p>"
        )
        parts.append(
            table_html(
                peaks,
                [
                    "study",
                    "subset",
                    "mu upper guaranteed [-]",
                    "mu lower [-]",
                    "mu upper [-]",
                    "gap [%]",
                    *location,
                    "frequency [Hz]",
                    "configuration",
                    "margin [-]",
                ],
            )
        )
    parts += ["<h3>Figures</h3>", figures_html(results.figures("analysis"), "analysis figures")]
    parts.append("<h3>Worst cases (destabilizing perturbations, physical values)</h3>")
    table = results.perturbations
    if table is None:
        parts.append(not_run("analysis stage (analysis/worst_perturbations.parquet)"))
    else:
        table = table.copy()
        physical = _physical_column(results)
        if physical is None:
            table["physical body"] = "not checked (confirm not run)"
        else:
            keys = list(zip(table["study"], table["subset"], strict=True))
            table["physical body"] = [
                ("yes" if bool(physical[k]) else "no") if k in physical.index else "not checked"
                for k in keys
            ]
        parts.append(
            "<p>Values in the block's unit (column <code>unit</code>); a worst case is a "
            "physical body when the confirmation found its scale within the physical domain.</p>"
        )
        parts.append(
            table_html(
                table,
                [
                    "study",
                    "subset",
                    "block",
                    "kind",
                    "unit",
                    "destabilizing value [unit]",
                    "in set value [unit]",
                    "normalized norm [-]",
                    "physical body",
                ],
            )
        )
    return "".join(parts)


def confirmation_section(results: RunResults) -> str:
    """The stability boundary on the twin (continuous, sampled, nonlinear) and the margins."""
    parts = ["<h3>Worst cases on the Drake twin</h3>"]
    parts.append(
        table_html(
            results.confirmation,
            [
                "study",
                "subset",
                "mu lower [-]",
                "mu upper [-]",
                "critical frequency [Hz]",
                "alpha linear continuous [-]",
                "alpha linear sampled [-]",
                "alpha nonlinear [-]",
                "alpha physical max [-]",
                "oscillation frequency [Hz]",
                "status",
            ],
            what="confirm stage (confirm/confirmation.parquet)",
        )
    )
    parts.append(figures_html(results.figures("confirm"), "confirmation figures"))
    parts.append("<h3>Worst-case performance on the Drake twin</h3>")
    parts.append(
        "<p>Per channel and uncertainty subset, the analysis' worst-case gain (its certified "
        "interval), the linear twin and the sampled-data prediction, and the Drake twin run "
        "with the worst perturbation and the worst input (a sinusoid at the critical frequency "
        "along the worst direction). Gains are ratios to the requirement (e_p: the APE "
        "requirement, e_u: the torque limit): above 1 the requirement is violated.</p>"
    )
    parts.append(
        table_html(
            results.performance,
            [
                "channel",
                "subset",
                "time [s]",
                "frequency [Hz]",
                "gain nominal [-]",
                "gain lower [-]",
                "gain upper [-]",
                "gain linear twin [-]",
                "gain linear sampled [-]",
                "gain twin [-]",
                "peak ratio twin [-]",
                "status",
            ],
            what="performance confirmation (confirm/performance_confirmation.parquet)",
        )
    )
    parts.append("<h3>Margins over the mission</h3>")
    margins = results.margins
    if margins is None:
        parts.append(not_run("margins stage (margins/margins.parquet)"))
    else:
        columns = [
            c
            for c in (
                "gain margin upper [dB]",
                "gain margin lower [dB]",
                "phase margin [deg]",
                "delay margin [s]",
                "disk margin [-]",
                "multiloop disk margin [-]",
            )
            if c in margins.columns
        ]
        worst = margins.groupby("loop")[columns].min().reset_index()
        parts.append("<p>Worst value over the mission's configurations, per loop model.</p>")
        parts.append(table_html(worst))
        rows = []
        for column, (threshold, unit) in REFERENCE_MARGINS.items():
            if column in margins.columns:
                value = float(margins[column].min())
                rows.append(
                    (
                        column,
                        f"{_value(value, unit)} against {_value(threshold, unit)} "
                        + badge("reference", bool(value >= threshold)),
                    )
                )
        parts.append(rows_html(rows))
        parts.append(figures_html(results.figures("margins"), "margins figure"))
    return "".join(parts)


def campaign_section(results: RunResults) -> str:
    """Probabilities with their intervals, worst runs, regions and figures."""
    if results.campaign is None:
        return not_run("campaign (no campaign-* folder)")
    parts = [f"<p>folder <code>{_e(results.campaign.name)}</code></p>"]
    parts.append("<h3>Probabilities of violation (95 % intervals)</h3>")
    parts.append(
        table_html(
            results.campaign_summary,
            [
                "metric",
                "requirement",
                "runs",
                "violations",
                "P(violation)",
                "P 95 % low",
                "P 95 % high",
                "interval",
                "min",
                "p50",
                "p95",
                "max",
            ],
            what="campaign report (report/summary.parquet)",
        )
    )
    parts.append(
        "<p>P columns are probabilities [-]; the metric columns are in the metric's unit "
        "(its name).</p>"
    )
    parts.append("<h3>Runs per status</h3>")
    parts.append(table_html(results.campaign_status, what="report/status.parquet"))
    parts.append("<h3>Violations: mission phase and time of the first violation</h3>")
    violations = results.violations
    if violations is not None and not violations.empty and "phase" in violations.columns:
        per_phase = violations.groupby("phase").size().rename("violations").reset_index()
        parts.append(table_html(per_phase))
        shown = violations.head(50)
        if len(violations) > 50:
            parts.append(f"<p>first 50 of {len(violations)} (all in report/violations.parquet)</p>")
        parts.append(table_html(shown))
    elif violations is not None and violations.empty:
        parts.append("<p>no run violated a requirement</p>")
    else:
        parts.append(not_run("report/violations.parquet"))
    parts.append("<h3>Worst runs (their dispersed values: report/worst_runs.parquet)</h3>")
    worst = results.worst_runs
    metrics = []
    if results.campaign_summary is not None and "metric" in results.campaign_summary:
        metrics = [m for m in results.campaign_summary["metric"] if m != ANY_FAILURE]
    parts.append(
        table_html(
            worst.head(10) if worst is not None else None,
            [
                "run_id",
                "requirement ratio [-]",
                "region",
                "weight",
                "window start [s]",
                "window end [s]",
                "frequency [Hz]",
                *metrics,
                "status",
            ],
            what="report/worst_runs.parquet",
        )
    )
    parts.append("<h3>Regions of the mu-guided sampler</h3>")
    parts.append(table_html(results.regions, what="report/regions.parquet"))
    parts.append("<h3>Figures</h3>")
    parts.append(figures_html(results.figures(results.campaign / "report"), "campaign figures"))
    return "".join(parts)


def validation_section(results: RunResults) -> str:
    """The Drake-vs-TITOP validation table."""
    if results.validation is None:
        return not_run("validate stage (validate/validate.txt)")
    return f"<pre>{_e(results.validation)}</pre>"


def replays_section(results: RunResults, report_dir: Path) -> str:
    """Links to the campaign's 3-D replays (relative to the report)."""
    if not results.replays:
        return not_run(
            "no 3-D replay in the campaign folder (make one: oos campaign replay DIR --case N)"
        )
    items = "".join(
        f'<li><a href="{_e(os.path.relpath(p, report_dir))}">{_e(p.name)}</a></li>'
        for p in results.replays
    )
    return f"<ul>{items}</ul>"


def _versions(results: RunResults) -> dict[str, str]:
    versions = {"python": platform.python_version(), "machine": platform.machine()}
    for package in VERSIONED_PACKAGES:
        try:
            versions[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            versions[package] = "absent"
    return versions


def provenance_section(results: RunResults) -> str:
    """Versions, the scenario's SHA-256 and the wall time of each stage."""
    record = results.scenario_record
    path = results.scenario_file
    rows = [("scenario file", f"<code>{_e(path)}</code>")]
    recorded = record.get("sha256")
    current = hashlib.sha256(path.read_bytes()).hexdigest() if path and path.is_file() else None
    rows.append(("scenario SHA-256 (recorded by the analysis)", f"<code>{_e(recorded)}</code>"))
    rows.append(("scenario SHA-256 (file now)", f"<code>{_e(current)}</code>"))
    if recorded and current:
        rows.append(
            ("file unchanged since the analysis", badge("same SHA-256", recorded == current))
        )
    versions = _versions(results)
    campaign = results.campaign_environment or {}
    table = pd.DataFrame(
        {
            "package": list(versions),
            "report (now)": list(versions.values()),
            "campaign run": [campaign.get(k, "") for k in versions],
        }
    )
    timings = (results.timings or {}).get("stages_s", {})
    stages = sorted(set(results.stage_seconds) | set(timings), key=_stage_order)
    wall = pd.DataFrame(
        {
            "stage": stages,
            "computation [s]": [results.stage_seconds.get(s, math.nan) for s in stages],
            "last oos run [s]": [
                math.nan if timings.get(s) is None else float(timings[s]) for s in stages
            ],
        }
    )
    total = (results.timings or {}).get("total_s")
    return "".join(
        [
            rows_html(rows),
            "<h3>Versions</h3>",
            table_html(table),
            "<h3>Wall time per stage</h3>",
            "<p><i>computation</i>: the run that produced the stage's folder "
            "(<code>stage.json</code>); <i>last oos run</i>: <code>timings.json</code> "
            "(n/a: up to date, skipped).</p>",
            table_html(wall) if stages else not_run("no stage timings (timings.json)"),
            f"<p>total of the last <code>oos run</code>: {_value(total, 's')}</p>",
        ]
    )


def _stage_order(name: str) -> tuple[int, str]:
    return (STAGES.index(name) if name in STAGES else len(STAGES), name)


#: Sections of the page: (anchor id, title).
SECTIONS = (
    ("headlines", "Headline numbers"),
    ("scenario", "Scenario"),
    ("controller", "Controller"),
    ("analysis", "Robust analysis"),
    ("confirmation", "Confirmation on the twin and margins"),
    ("campaign", "Campaign"),
    ("validation", "Drake vs TITOP validation"),
    ("replays", "3-D replays"),
    ("provenance", "Versions, scenario hash and wall times"),
)


def _guarded(render, *args) -> str:
    """A section's HTML; an error while rendering it is shown in its place."""
    try:
        return render(*args)
    except Exception as error:  # noqa: BLE001 - one broken table must not lose the report
        return not_run(f"section failed to render: {type(error).__name__}: {error}")


def render_report(results: RunResults, report_dir: str | Path | None = None) -> str:
    """The whole report of ``results`` as one HTML string.

    Parameters
    ----------
    results : RunResults
    report_dir : path-like, optional
        Folder the page will be written to (links to the replays are relative to it; default:
        the results folder).

    Returns
    -------
    str
    """
    report_dir = Path(report_dir) if report_dir is not None else results.out
    try:
        numbers = headline_numbers(results)
        headlines = headlines_html(numbers)
    except Exception as error:  # noqa: BLE001 - a changed table must not lose the report
        numbers = []
        headlines = not_run(f"headline numbers: {type(error).__name__}: {error}")
    bodies = {
        "headlines": headlines,
        "scenario": _guarded(scenario_section, results),
        "controller": _guarded(controller_section, results, numbers),
        "analysis": _guarded(analysis_section, results),
        "confirmation": _guarded(confirmation_section, results),
        "campaign": _guarded(campaign_section, results),
        "validation": _guarded(validation_section, results),
        "replays": _guarded(replays_section, results, report_dir),
        "provenance": _guarded(provenance_section, results),
    }
    nav = "".join(f'<a href="#{key}">{_e(title)}</a>' for key, title in SECTIONS)
    sections = "".join(
        f'<section id="{key}"><h2>{_e(title)}</h2>{bodies[key]}</section>'
        for key, title in SECTIONS
    )
    scenario = results.scenario_record.get("name") or (
        results.scenario_file.stem if results.scenario_file else "unknown scenario"
    )
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<meta http-equiv="Content-Security-Policy" content="{_CSP}">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>oos run report: {_e(scenario)}</title><style>{_STYLE}</style></head><body>"
        f"<header><h1>oos run report: {_e(scenario)}</h1>"
        f"<p>results folder <code>{_e(results.out.resolve())}</code></p>"
        f"<p>written {now}</p></header><nav>{nav}</nav><main>{sections}</main></body></html>\n"
    )


def write_report(
    out: str | Path,
    campaign: str | Path | None = None,
    path: str | Path | None = None,
    *,
    report_dir: str | Path | None = None,
) -> Path:
    """Read the results folder ``out`` and write its report (atomically).

    Parameters
    ----------
    out : path-like
        The ``oos run --out`` folder.
    campaign : path-like, optional
        Its campaign folder (default: the newest ``campaign-*``).
    path : path-like, optional
        Where to write the page (default: ``out/report.html``).
    report_dir : path-like, optional
        Folder the page will be opened from, when it is copied there after (its links to the
        replays are relative to it; default: the folder of ``path``).

    Returns
    -------
    pathlib.Path
        The page written.
    """
    from oos_drake.report.results import load_run

    results = load_run(out, campaign)
    path = Path(path) if path is not None else Path(out) / REPORT_FILE
    text = render_report(results, report_dir or path.parent).encode("utf-8")
    return atomic_write_bytes(path, lambda stream: stream.write(text))
