"""The table convention of the package: one rule set for every column a result table carries.

Every table the pipeline writes (Parquet/CSV in the stage folders) names a quantity's column
``name [unit]`` (``[-]`` when dimensionless; labels, indices and flags carry no unit), with
words separated by spaces, one spelling per quantity across tables, and frequencies in Hz.
Function arguments and result fields stay in SI (rad/s for angular frequencies, as in MATLAB)
with the unit in the name where it is not SI (``_hz``).

Underscores are allowed only inside *identifiers*: the names of uncertain blocks
(``Jxx_RH2``, ``k_shear_SM1``, ``w1_SA1``), of simulator signals and metrics
(:data:`IDENTIFIERS`, ``peak_torque``, ``theta_hub``) and of vector components
(``phi_x``, ``u_z``). tests/test_table_columns.py applies :func:`column_problem` to every column
name the library spells out (a static scan of the source) and to the mu sweep schema of
:mod:`oos_drake.robust.tables`.
"""

from __future__ import annotations

import re

__all__ = ["CONVERTED", "IDENTIFIERS", "RENAMED", "column_problem", "quantity_key"]

#: Metric and signal names of the shipped simulators (identifiers: they appear in campaign
#: specs and requirements, so they keep their underscores inside column names).
IDENTIFIERS = frozenset(
    {
        "ape",
        "peak_torque",
        "peak_applied_torque",
        "rms_attitude",
        "theta_hub",
        "omega_hub",
        "deflection_array",
        "theta_target_rel",
        "torque_command",
        "torque_applied",
        "noise_seed",
    }
)

#: Column names renamed to this convention (old -> new; issue 34): result folders written
#: before carry the old names.
RENAMED = {
    "cpu_time [s]": "cpu time [s]",
    "wall_time [s]": "wall time [s]",
    "window_start [s]": "window start [s]",
    "window_end [s]": "window end [s]",
    "ape_max [rad]": "ape max [rad]",
    "ape_requirement [rad]": "ape requirement [rad]",
    "torque_max [N m]": "torque max [N m]",
    "torque_requirement [N m]": "torque requirement [N m]",
    "gain_lower [-]": "gain lower [-]",
    "gain_nominal [-]": "gain nominal [-]",
    "gain_upper [-]": "gain upper [-]",
    "mu_upper_alone [-]": "mu upper alone [-]",
    "mu_upper_total [-]": "mu upper total [-]",
    "mu_upper_without [-]": "mu upper without [-]",
    "mu_upper [-]": "mu upper [-]",
    "mu_lower [-]": "mu lower [-]",
    "margin_lower [-]": "margin lower [-]",
    "margin_upper [-]": "margin upper [-]",
    "mission mu_upper [-]": "mission mu upper [-]",
    "mission mu_lower [-]": "mission mu lower [-]",
    "normalized_real [-]": "normalized real [-]",
    "normalized_imag [-]": "normalized imag [-]",
    "normalized_norm [-]": "normalized norm [-]",
    "destabilizing_value [unit]": "destabilizing value [unit]",
    "in_set_value [unit]": "in set value [unit]",
    "peak frequency [rad/s]": "peak frequency [Hz]",  # values converted, not only renamed
    "gap_at_critical [%]": "gap at critical [%]",
    "peak_model": "peak model",
    "peak_frequency [Hz]": "peak frequency [Hz]",
    "lower_source": "lower source",
    "spike_rounds": "spike rounds",
    "spikes_left": "spikes left",
    "spikes_converged": "spikes converged",
    "refinement_points": "refinement points",
    "searched_models": "searched models",
    "spike_stop": "spike stop",
    "budget_exhausted": "budget exhausted",
    "spike_time [s]": "spike time [s]",
    "spike_work [point-iterations]": "spike work [point-iterations]",
    "gap_guaranteed [%]": "gap guaranteed [%]",
    "margin_guaranteed [-]": "margin guaranteed [-]",
    "guarantee_slack [%]": "guarantee slack [%]",
    "guarantee_solved_points": "guarantee solved points",
    "guarantee_raised_configurations": "guarantee raised configurations",
    "guarantee_failures": "guarantee failures",
    "guarantee_time [s]": "guarantee time [s]",
    "guarantee_scope": "guarantee scope",
}

#: Old names in :data:`RENAMED` whose values changed unit too: a reader must not only rename them.
CONVERTED = frozenset({"peak frequency [rad/s]"})

_WITH_UNIT = re.compile(r"(?P<name>[^\[\]]+?) \[(?P<unit>[^\[\]]+)\]")
#: Words that name a frequency: their column is in Hz.
_FREQUENCY_WORDS = ("frequency", "crossover")


def _is_identifier(token: str) -> bool:
    """A block, signal or metric name, or a placeholder of a generated name (``{}``)."""
    token = token.split(":")[-1]  # "wc:Jxx_RH2", "wcgain:peak_torque"
    return (
        token in IDENTIFIERS
        or "{}" in token
        or any(c.isupper() or c.isdigit() for c in token)
        or re.fullmatch(r"[a-z]+_[xyz]", token) is not None
    )


def column_problem(column: str) -> str | None:
    """What is wrong with the column name ``column``, or ``None`` when it follows the rules.

    Parameters
    ----------
    column : str
        A column name; ``{}`` stands for a generated part (an f-string placeholder).

    Returns
    -------
    str or None
        One line naming the broken rule.
    """
    if "[" in column or "]" in column:
        match = _WITH_UNIT.fullmatch(column)
        if match is None:
            return f"{column!r}: a unit goes last, as 'name [unit]'"
        name, unit = match["name"], match["unit"]
    else:
        name, unit = column, None
    if name != name.strip() or "  " in name:
        return f"{column!r}: stray spaces"
    for token in name.split(" "):
        if "_" in token and not _is_identifier(token):
            return f"{column!r}: words are separated by spaces, not underscores ({token!r})"
    words = name.lower().split(" ")
    if unit is not None and any(w in _FREQUENCY_WORDS for w in words) and unit != "Hz":
        return f"{column!r}: frequencies are in Hz in tables"
    if unit == "rad/s" and not (len(words) == 1 and _is_identifier(name)):
        return f"{column!r}: rad/s only for a block or signal in its own unit; tables speak Hz"
    return None


def quantity_key(column: str) -> str:
    """The spelling-blind key of a column (case, underscores and spaces folded): two columns of
    one quantity spelled differently (``mu upper [-]``, ``mu_upper [-]``) share it."""
    return re.sub(r"[\s_]+", " ", column.lower()).strip()
