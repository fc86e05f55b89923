"""PNG figures of the analysis (paper Figs. muanalysis, performance, mu_analysis_SM, ...), the
margins and the confirmation on the twin."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from oos_drake.analysis.subsets import SUBSET_ORDER


def pyplot():
    """``matplotlib.pyplot`` on the non-interactive Agg backend (figures go to files)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, *, dpi: int = 120, tight: bool = True) -> Path:
    """Write ``fig`` to ``path`` (PNG at ``dpi``, atomically), after ``tight_layout`` if
    ``tight``; close it and return the path."""
    from oos_drake.files import atomic_write_bytes

    if tight:
        fig.tight_layout()
    try:
        return atomic_write_bytes(path, lambda stream: fig.savefig(stream, dpi=dpi, format="png"))
    finally:
        pyplot().close(fig)


def _ordered(names):
    return [s for s in SUBSET_ORDER if s in set(names)] + sorted(set(names) - set(SUBSET_ORDER))


def _guaranteed_line(axes, value, suffix):
    """The peak upper bound proved on the whole frequency axis, as a line on each of ``axes``."""
    if value is None or not np.isfinite(value):
        return
    for a in axes:
        a.axhline(value, color="k", ls="-.", lw=0.9, label=f"upper, all frequencies {suffix}")


def mu_mission_figure(sweep: pd.DataFrame, common_hz, peaks: pd.DataFrame, path) -> Path:
    """(a) surface of the total-set upper bound over time x frequency; (b) side views."""
    plt = pyplot()
    fig = plt.figure(figsize=(17, 5.8))
    # the 3-D panel gets the most room: its labels need it
    layout = fig.add_gridspec(1, 3, width_ratios=(1.45, 1.0, 1.0), wspace=0.28)
    total = sweep[(sweep["subset"] == "total") & ~sweep["refined"]]
    total = total[np.isin(total["frequency [Hz]"].to_numpy(), common_hz)]
    grid = total.pivot_table(index="time [s]", columns="frequency [Hz]", values="mu upper [-]")
    # (computed_zorder off: the peak's marker is drawn over the surface, not hidden behind it)
    ax = fig.add_subplot(layout[0], projection="3d", computed_zorder=False)
    _mu_surface(fig, ax, grid, peaks)
    ax2 = fig.add_subplot(layout[1])
    ax3 = fig.add_subplot(layout[2])
    for name in _ordered(sweep["subset"].unique()):
        part = sweep[sweep["subset"] == name]
        by_f = part.groupby("frequency [Hz]")["mu upper [-]"].max()
        by_t = part.groupby("time [s]")["mu upper [-]"].max()
        ax2.semilogx(by_f.index, by_f.to_numpy(), label=name, lw=1.2)
        ax3.plot(by_t.index, by_t.to_numpy(), label=name, lw=1.2)
    for _, row in peaks.iterrows():
        if row["subset"] == "total":
            ax2.plot(
                row["frequency [Hz]"], row["mu lower [-]"], "kv", ms=7, label="certified lower"
            )
            ax3.plot(row["time [s]"], row["mu lower [-]"], "kv", ms=7)
            _guaranteed_line((ax2, ax3), row.get("mu upper guaranteed [-]"), "(total)")
    ax2.set_xlabel("frequency [Hz]")
    ax2.set_ylabel("max over time of mu upper bound [-]")
    ax2.set_title("(b) side view: frequency")
    ax3.set_xlabel("time [s]")
    ax3.set_ylabel("max over frequency of mu upper bound [-]")
    ax3.set_title("(b) side view: time")
    for a in (ax2, ax3):
        a.grid(True, which="both", alpha=0.3)
        a.axhline(1.0, color="r", ls="--", lw=0.8)
    ax2.legend(fontsize=8)
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.12, top=0.9)
    return save_figure(fig, path, tight=False)


def _mu_surface(fig, ax, grid: pd.DataFrame, peaks: pd.DataFrame) -> None:
    """The surface of mu's upper bound over time [s] x frequency [Hz] (log axis labelled in Hz),
    seen from the low-time, high-frequency corner so that the ridge stands in front of the
    low-frequency plateau, with a colour bar and the certified peak of the total set marked."""
    import matplotlib.ticker as ticker

    times = grid.index.to_numpy(dtype=float)
    log_f = np.log10(grid.columns.to_numpy(dtype=float))
    T, F = np.meshgrid(times, log_f, indexing="ij")
    values = grid.to_numpy(dtype=float)
    surface = ax.plot_surface(
        T, F, values, cmap="viridis", linewidth=0, antialiased=True, rstride=1, cstride=1
    )
    decades = np.arange(np.floor(log_f.min()), np.ceil(log_f.max()) + 1)
    ax.yaxis.set_major_locator(ticker.FixedLocator(decades))
    ax.yaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{10**v:g}"))
    ax.set_ylim(log_f.min(), log_f.max())
    ax.set_xlabel("time [s]", labelpad=8)
    ax.set_ylabel("frequency [Hz] (log scale)", labelpad=8)
    ax.set_zlabel("")  # the colour bar says what the height is
    ax.view_init(elev=24, azim=-52)
    ax.set_box_aspect((1.5, 1.2, 0.75))
    ax.tick_params(labelsize=8, pad=1)
    total = peaks[peaks["subset"] == "total"] if "subset" in peaks else peaks.iloc[:0]
    if len(total) and {"time [s]", "frequency [Hz]", "mu lower [-]"} <= set(total.columns):
        row = total.iloc[0]
        mu_peak = float(row.get("mu upper [-]", row["mu lower [-]"]))
        ax.scatter(
            [row["time [s]"]],
            [np.log10(row["frequency [Hz]"])],
            [mu_peak],
            color="red",
            s=40,
            depthshade=False,
            zorder=10,
            label=f"certified peak: mu <= {mu_peak:.3g} at t = {row['time [s]']:.0f} s, "
            f"f = {row['frequency [Hz]']:.3g} Hz",
        )
        ax.legend(loc="upper left", fontsize=8, bbox_to_anchor=(0.0, 1.0))
    bar = fig.colorbar(surface, ax=ax, shrink=0.6, pad=0.13, fraction=0.04)
    bar.set_label("mu upper bound, Delta_tot [-]")
    ax.set_title("(a) mu upper bound over the mission, Delta_tot")


def performance_figure(table: pd.DataFrame, path) -> Path:
    """Worst-case gain upper bounds per subset, max over the analyzed configurations."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8))
    titles = {"e_p": "(a) d -> e_p (APE / requirement)", "e_u": "(b) d -> e_u (torque / 2 N m)"}
    for ax, channel in zip(axes, ["e_p", "e_u"], strict=True):
        part = table[table["channel"] == channel]
        nominal = part.groupby("frequency [Hz]")["gain nominal [-]"].max()
        ax.loglog(nominal.index, nominal.to_numpy(), "k--", lw=1.5, label="nominal")
        for name in _ordered(part["subset"].unique()):
            g = part[part["subset"] == name].groupby("frequency [Hz]")["gain upper [-]"].max()
            ax.loglog(g.index, g.to_numpy(), lw=1.2, label=name)
        ax.axhline(1.0, color="r", ls=":", lw=0.8, label="requirement")
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel("worst-case gain upper bound [-]")
        ax.set_title(titles[channel])
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    return save_figure(fig, path)


def docking_figure(sweeps: dict, peaks: dict, path) -> Path:
    """Side views of mu (Delta_tot) over the swept stiffness and over frequency, per phase.

    ``sweeps``: phase -> the ``docking_<phase>`` table (``stiffness [N/m or N m/rad]``);
    ``peaks``: phase -> the docking peak's numbers of ``summary.json``.
    """
    plt = pyplot()
    n = len(sweeps)
    fig, axes = plt.subplots(n, 2, figsize=(13, 4.2 * n), squeeze=False)
    for row, (phase, sweep) in enumerate(sweeps.items()):
        part = sweep[sweep["subset"] == "total"]
        by_k = part.groupby("stiffness [N/m or N m/rad]")["mu upper [-]"].max()
        by_f = part.groupby("frequency [Hz]")["mu upper [-]"].max()
        ax1, ax2 = axes[row]
        ax1.semilogx(by_k.index, by_k.to_numpy(), lw=1.3)
        ax2.semilogx(by_f.index, by_f.to_numpy(), lw=1.3)
        pk = peaks.get(phase)
        if pk is not None:
            ax1.plot(pk["stiffness"], pk["mu_lower"], "kv", ms=7, label="certified lower")
            ax2.plot(pk["frequency [Hz]"], pk["mu_lower"], "kv", ms=7, label="certified lower")
            _guaranteed_line((ax1, ax2), pk.get("mu_upper_guaranteed"), "")
            ax1.legend(fontsize=8)
        ax1.set_xlabel("stiffness of the swept spring-damper [N/m or N m/rad]")
        ax2.set_xlabel("frequency [Hz]")
        for a in (ax1, ax2):
            a.set_ylabel("mu upper bound, Delta_tot [-]")
            a.axhline(1.0, color="r", ls="--", lw=0.8)
            a.grid(True, which="both", alpha=0.3)
            a.set_title(f"docking phase {phase}")
    return save_figure(fig, path)


def sensitivity_figure(table: pd.DataFrame, path) -> Path:
    """Bars: drop of the peak without each block, and its mu-sensitivity."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8))
    t = table.sort_values("drop [%]", ascending=True)
    axes[0].barh(t["block"], t["drop [%]"])
    axes[0].set_xlabel("drop of the mu peak with the block nominal [%]")
    t2 = table.sort_values("sensitivity [-]", ascending=True)
    axes[1].barh(t2["block"], t2["sensitivity [-]"], color="tab:orange")
    axes[1].set_xlabel("mu-sensitivity (d mu / mu) / (d r / r) [-]")
    for a in axes:
        a.grid(True, axis="x", alpha=0.3)
    fig.suptitle("Which uncertainty moves the worst-case mu (critical configuration)")
    return save_figure(fig, path)


def time_check_figure(signals: pd.DataFrame, summary: pd.DataFrame, path) -> Path:
    """Pointing error and torque of the perturbed closed loops against the requirements."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8))
    for case, part in signals.groupby("case", sort=False):
        t = part["t [s]"].to_numpy()
        phi = np.abs(part[[f"phi_{a} [rad]" for a in "xyz"]].to_numpy()).max(axis=1)
        u = np.abs(part[[f"u_{a} [N m]" for a in "xyz"]].to_numpy()).max(axis=1)
        axes[0].plot(t, phi, lw=1.0, label=case)
        axes[1].plot(t, u, lw=1.0, label=case)
    if len(summary):
        axes[0].axhline(
            summary["ape requirement [rad]"].iloc[0], color="r", ls="--", label="APE requirement"
        )
        axes[1].axhline(
            summary["torque requirement [N m]"].iloc[0], color="r", ls="--", label="torque bound"
        )
    axes[0].set_ylabel("max_axis |phi| [rad]")
    axes[1].set_ylabel("max_axis |u| [N m]")
    for a in axes:
        a.set_xlabel("time [s]")
        a.set_yscale("log")
        top = a.get_ylim()[1]
        a.set_ylim(top * 1e-4, top)
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle("Linear time-domain check: d_ext = step + sine at the critical frequency")
    return save_figure(fig, path)


def open_loop_figure(table: pd.DataFrame, title: str, path) -> Path:
    """One panel per subset: sampled gains (grey) over the nominal (black)."""
    plt = pyplot()
    names = _ordered([s for s in table["subset"].unique() if s != "nominal"])
    cols = 3
    rows = int(np.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(14, 3.6 * rows), squeeze=False)
    nominal = table[table["subset"] == "nominal"]
    for ax, name in zip(axes.ravel(), names, strict=False):
        for _, part in table[table["subset"] == name].groupby("sample"):
            ax.semilogx(part["frequency [Hz]"], part["gain [dB]"], color="0.6", lw=0.6)
        ax.semilogx(nominal["frequency [Hz]"], nominal["gain [dB]"], "k", lw=1.3)
        ax.set_title(name)
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel("gain [dB]")
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[len(names) :]:
        ax.set_visible(False)
    fig.suptitle(title)
    return save_figure(fig, path)


def analysis_figures(result, out) -> dict[str, Path]:
    """Every figure of an :class:`~oos_drake.analysis.results.AnalysisResult` in ``out``.

    Returns
    -------
    dict
        Name (``"mu_mission_png"``, ...) -> path, for ``summary.json``'s files.
    """
    out = Path(out)
    paths = {}
    if result.time_signals is not None:
        paths["time_check_png"] = time_check_figure(
            result.time_signals, result.time_check, out / "time_check.png"
        )
    if result.open_loop is not None:
        paths["open_loop_png"] = open_loop_figure(
            result.open_loop, result.open_loop_title, out / "open_loop_effects.png"
        )
    paths["mu_mission_png"] = mu_mission_figure(
        result.mission, result.grid_hz, result.mission_peaks, out / "mu_mission.png"
    )
    paths["performance_png"] = performance_figure(result.performance, out / "performance.png")
    if result.docking:
        paths["docking_png"] = docking_figure(
            result.docking, result.docking_peaks, out / "mu_docking.png"
        )
    if result.sensitivity is not None:
        paths["sensitivity_png"] = sensitivity_figure(result.sensitivity, out / "sensitivity.png")
    return paths


def margins_figure(table: pd.DataFrame, path, rate_hz: float) -> Path:
    """Margins over the mission: gain, phase, delay and disk margins, continuous (solid),
    exact sampled (dashed), per channel; the multiloop disk margin in black."""
    plt = pyplot()

    fig, axes = plt.subplots(2, 2, figsize=(13, 8), sharex=True)
    panels = [
        ("gain margin upper [dB]", "gain margin, gain increase [dB]"),
        ("phase margin [deg]", "phase margin [deg]"),
        ("delay margin [s]", "delay margin [s]"),
        ("disk margin [-]", "balanced disk margin alpha [-]"),
    ]
    styles = {"continuous": "-", "sampled": "--"}
    colors = {"u_x": "C0", "u_y": "C1", "u_z": "C2"}
    for ax, (column, label) in zip(axes.ravel(), panels, strict=True):
        for loop, ls in styles.items():
            part = table[table["loop"] == loop]
            for channel, color in colors.items():
                one = part[part["channel"] == channel]
                ax.plot(
                    one["time [s]"],
                    one[column],
                    ls=ls,
                    color=color,
                    lw=1.1,
                    label=f"{channel}, {loop}",
                )
            if column == "disk margin [-]":
                one = part[part["channel"] == "u_x"]
                ax.plot(
                    one["time [s]"],
                    one["multiloop disk margin [-]"],
                    ls=ls,
                    color="k",
                    lw=1.3,
                    label=f"multiloop, {loop}",
                )
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("mission time [s]")
    axes[0, 0].legend(fontsize=7, ncol=2)
    axes[1, 1].legend(fontsize=7, ncol=2)
    fig.suptitle(
        "Loop-at-a-time margins at the wheel input (others closed) and disk margins: "
        f"continuous loop (solid) vs exact {rate_hz:g} Hz sampled-data loop (dashed)"
    )
    return save_figure(fig, path)


def confirmation_figures(result, out) -> list[Path]:
    """One :func:`confirmation_figure` per peak of a
    :class:`~oos_drake.analysis.confirm.ConfirmationResult` with nonlinear runs:
    ``out/confirmation_<study>_<subset>.png``; their paths (each cut at its run's settling
    time, :meth:`~oos_drake.analysis.confirm.ConfirmOptions.for_peak`)."""
    twin = result.options.twin
    return [
        confirmation_figure(
            part,
            row,
            Path(out) / f"confirmation_{row['study']}_{row['subset']}.png",
            twin.for_peak(
                row.get("frequency linear sampled [Hz]", math.nan),
                row.get("critical frequency [Hz]", math.nan),
            ).settle,
        )
        for row, part in result.peak_histories()
    ]


def confirmation_figure(histories: pd.DataFrame, row, path, settle: float) -> Path:
    """Hub attitude on both sides of the nonlinear boundary of one peak (PNG): the window the
    oscillation is identified on (after ``settle`` [s]), each axis about its mean over the second
    half (given in the legend), scaled to the critical oscillation there (the transient leaves
    the plot)."""
    from oos_drake.analysis.confirm import AXES

    plt = pyplot()

    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True, constrained_layout=True)
    for ax, side in zip(axes, ("stable", "unstable"), strict=True):
        part = histories[(histories["side"] == side) & (histories["time [s]"] >= settle)]
        if part.empty:
            ax.text(0.5, 0.5, f"no {side} run", ha="center", transform=ax.transAxes)
            continue
        alpha = float(part["alpha [-]"].iloc[0])
        # zoom on the second half of the window: the critical oscillation, not the transient,
        # about its mean (a realized Delta_add leaves the hub attitude at an offset)
        tail = part[part["time [s]"] >= 0.5 * (settle + part["time [s]"].max())]
        columns = [f"phi_{a} [rad]" for a in AXES]
        offset = tail[columns].mean()
        for a, column in zip(AXES, columns, strict=True):
            ax.plot(
                part["time [s]"],
                1e6 * (part[column] - offset[column]),
                label=f"{a} axis ({1e6 * offset[column]:+.0f} urad)",
            )
        top = 1.5e6 * float(np.abs((tail[columns] - offset).to_numpy()).max())
        if top > 0:
            ax.set_ylim(-top, top)
        ax.set_ylabel("hub attitude error - mean [urad]")
        ax.set_title(f"{side} side: alpha = {alpha:.4f}", fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel(f"time since the window start [s] (first {settle:g} s of transient cut)")
    fig.suptitle(
        f"{row['study']} / {row['subset']}: nonlinear boundary alpha = "
        f"{row['alpha nonlinear [-]']:.4f} (linear sampled {row['alpha linear sampled [-]']:.4f}, "
        f"continuous {row['alpha linear continuous [-]']:.4f})",
        fontsize=10,
    )
    return save_figure(fig, path, dpi=110, tight=False)
