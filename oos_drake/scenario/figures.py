"""Model figures of the paper's section 2 (PNG) with their numbers (CSV / Parquet).

* ``sigma_moments``: gain of ``T_ext{1} -> wdot{1}`` at the six moments, nominal and uncertain
  samples (paper Fig. sigma_plot);
* ``docking_sweeps``: gain of ``T_ext{2} -> wdot{2}`` for the docking phases with the stiffness
  swept from 0.1 to 1e5 and damping 100 (Fig. sigma_plot_springmass a, b, c);
* ``inertias``: inertia tensor entries at G1 in R_RH1 over the mission, from the model's static
  gain (Fig. inertias);
* ``surface``: gain of ``T_ext{1} -> phi{1}`` over time and frequency (Fig. surf).

Every ``*_data`` function returns a tidy :class:`pandas.DataFrame` (SI units, frequencies in Hz,
gains in dB); :func:`make_figures` writes them and the PNGs.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from oos_drake.lfr import usample, usubs
from oos_drake.titop.parameters import spring_damper_values

__all__ = [
    "FigureFiles",
    "sigma_moments_data",
    "docking_sweeps_data",
    "inertia_history_data",
    "surface_data",
    "make_figures",
]

#: Channel indices in the 6-vectors [Fx Fy Fz Tx Ty Tz] / [ax ay az wdot_x wdot_y wdot_z].
TORQUE_X, TORQUE_Y = 3, 4


@dataclass(frozen=True)
class FigureFiles:
    """Files written by :func:`make_figures`: ``{figure name: (png path, data path)}``."""

    files: dict

    def __iter__(self):
        return iter(self.files.items())


def _db(values) -> np.ndarray:
    return 20.0 * np.log10(np.maximum(np.abs(values), 1e-300))


def sigma_moments_data(model, timeline, frequencies_hz, n_samples: int = 20, rng=None):
    """Gain of ``T_ext{1} -> wdot{1}`` at the six moments (nominal and ``n_samples`` samples).

    Parameters
    ----------
    model : LFR
        Mission model (:func:`oos_drake.scenario.model.build_mission_model`).
    timeline : MissionTimeline
        Gives the six moments.
    frequencies_hz : array_like
        Frequency grid [Hz].
    n_samples : int
        Uncertain samples of ``Delta_real = diag(Delta_mec, Delta_mod)`` per moment.
    rng : numpy.random.Generator
        Sampling generator (default ``default_rng(0)``).

    Returns
    -------
    pandas.DataFrame
        Columns ``moment, time [s], model ("nominal" or "sample k"), frequency [Hz], gain [dB]``.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    omega = 2 * np.pi * np.asarray(frequencies_hz, dtype=float)
    rows = []
    for name, moment in timeline.moments.items():
        config = moment.configuration
        fixed = usubs(model, config.parameters())
        curves = {"nominal": fixed.nominal.freqresp(omega)[:, TORQUE_X, TORQUE_X]}
        if n_samples:
            samples, _ = usample(fixed, n_samples, rng)
            response = samples.freqresp(omega)[..., TORQUE_X, TORQUE_X]
            curves.update({f"sample {k}": response[k] for k in range(n_samples)})
        for label, gain in curves.items():
            rows.append(
                pd.DataFrame(
                    {
                        "moment": name,
                        "time [s]": float(config.time),
                        "model": label,
                        "frequency [Hz]": frequencies_hz,
                        "gain [dB]": _db(gain),
                    }
                )
            )
    return pd.concat(rows, ignore_index=True)


def docking_sweeps_data(timeline, frequencies_hz, stiffness=None):
    """Gain of ``T_ext{2} -> wdot{2}`` during docking (paper Fig. sigma_plot_springmass).

    Panels: ``a`` phase 7, SM1 stiffness swept (damping 100, SM2 open); ``b`` phase 8, SM2 swept
    while SM1 is rigid; ``c`` phase 8, SM1 swept (arm release) while SM2 is rigid. Uncertain
    mechanical and modal parameters are nominal.

    Parameters
    ----------
    timeline : MissionTimeline
        Gives the docking-phase configurations and the spring-damper settings.
    frequencies_hz : array_like
        Frequency grid [Hz].
    stiffness : array_like, optional
        Swept stiffness values [N/m or N m/rad] (default: the scenario's sweep, 0.1 .. 1e5).

    Returns
    -------
    pandas.DataFrame
        Columns ``panel, phase, swept, stiffness [N/m or N m/rad], frequency [Hz], gain [dB]``.
    """
    from oos_drake.scenario.model import build_docking_model

    scenario = timeline.scenario
    docking = scenario.docking
    stiffness = np.asarray(docking.stiffness_sweep if stiffness is None else stiffness, float)
    omega = 2 * np.pi * np.asarray(frequencies_hz, dtype=float)
    n = stiffness.size
    rows = []
    rigid = (docking.rigid_stiffness, docking.rigid_damping)
    panels = (
        ("a", "7", "SM1", {}),
        ("b", "8", "SM2", spring_damper_values("SM1", *rigid)),
        ("c", "8", "SM1", spring_damper_values("SM2", *rigid)),
    )
    for panel, phase, swept, fixed_springs in panels:
        model = build_docking_model(phase, scenario)  # cached per phase and scenario
        config = timeline.docking_phases[phase].configuration
        values = {
            k: np.full(n, float(v))
            for k, v in config.parameters().items()
            if k in model.occurrences
        }
        values.update({k: np.full(n, float(v)) for k, v in fixed_springs.items()})
        values.update(spring_damper_values(swept, stiffness, np.full(n, docking.damping)))
        response = usubs(model, values).nominal.freqresp(omega)[..., TORQUE_Y, TORQUE_Y]
        for k in range(n):
            rows.append(
                pd.DataFrame(
                    {
                        "panel": panel,
                        "phase": phase,
                        "swept": swept,
                        "stiffness [N/m or N m/rad]": stiffness[k],
                        "frequency [Hz]": frequencies_hz,
                        "gain [dB]": _db(response[k]),
                    }
                )
            )
    return pd.concat(rows, ignore_index=True)


def inertia_history_data(model, timeline, times):
    """Inertia tensor entries at G1 in R_RH1 over the mission, from the model's static gain.

    The rotational block of ``G(0)^-1`` (``G`` the nominal mission model) is the inertia of the
    whole connected system about G1 (paper Fig. inertias).

    Returns
    -------
    pandas.DataFrame
        Columns ``time [s]``, ``mass [kg]``, ``Jxx [kg m^2]`` ... ``Jyz [kg m^2]`` (products as
        the tensor's off-diagonal entries).
    """
    values = timeline.configuration(np.asarray(times, dtype=float)).parameters()
    gain = usubs(model, values).nominal.freqresp(np.array([0.0]))[:, 0].real
    inertia = np.linalg.inv(gain)
    return pd.DataFrame(
        {
            "time [s]": times,
            "mass [kg]": inertia[:, 0, 0],
            "Jxx [kg m^2]": inertia[:, 3, 3],
            "Jyy [kg m^2]": inertia[:, 4, 4],
            "Jzz [kg m^2]": inertia[:, 5, 5],
            "Jxy [kg m^2]": inertia[:, 3, 4],
            "Jxz [kg m^2]": inertia[:, 3, 5],
            "Jyz [kg m^2]": inertia[:, 4, 5],
        }
    )


def surface_data(model, timeline, times, frequencies_hz):
    """Gain of ``T_ext{1} -> phi{1}`` (nominal) over mission time x frequency (Fig. surf).

    Returns
    -------
    numpy.ndarray
        ``(len(times), len(frequencies_hz))`` gains [dB].
    """
    from oos_drake.scenario.model import attitude_model

    values = timeline.configuration(np.asarray(times, dtype=float)).parameters()
    fixed = usubs(model, values).nominal
    response = attitude_model(fixed).freqresp(2 * np.pi * np.asarray(frequencies_hz, float))
    return _db(response[..., 0, TORQUE_X])


def _write(frame: pd.DataFrame, path: Path) -> Path:
    frame.to_csv(path, index=False)
    return path


def make_figures(
    out_dir,
    scenario,
    *,
    n_times: int = 330,
    n_frequencies: int = 500,
    n_samples: int = 20,
    seed: int = 0,
    model=None,
) -> FigureFiles:
    """Compute the four model figures and write PNG + data files into ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Output folder (created).
    scenario : Scenario
    n_times, n_frequencies : int
        Mission grid (paper: 330 equally spaced times) and frequency grid (0.01 .. 100 Hz, log).
    n_samples : int
        Uncertain samples per moment in ``sigma_moments``.
    seed : int
        Seed of the sampling generator.
    model : LFR, optional
        Prebuilt mission model.

    Returns
    -------
    FigureFiles
        ``sigma_moments``, ``docking_sweeps``, ``inertias``, ``surface`` -> (PNG, data file).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from oos_drake.scenario.model import build_mission_model
    from oos_drake.scenario.timeline import mission_timeline

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    timeline = mission_timeline(scenario)
    model = build_mission_model(timeline.scenario) if model is None else model
    frequencies = np.logspace(-2, 2, n_frequencies)
    times = np.linspace(timeline.t_start, timeline.t_end, n_times)
    files = {}

    # -- Fig. sigma_plot
    sigma = sigma_moments_data(model, timeline, frequencies, n_samples, np.random.default_rng(seed))
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), sharex=True, sharey=True)
    for ax, (name, group) in zip(axes.flat, sigma.groupby("moment", sort=True), strict=False):
        for label, curve in group.groupby("model", sort=False):
            nominal = label == "nominal"
            ax.semilogx(
                curve["frequency [Hz]"],
                curve["gain [dB]"],
                color="tab:red" if nominal else "tab:blue",
                lw=1.6 if nominal else 0.5,
                alpha=1.0 if nominal else 0.35,
                zorder=3 if nominal else 1,
                label="nominal" if nominal else None,
            )
        ax.semilogx([], [], color="tab:blue", lw=0.5, label=f"{n_samples} uncertain samples")
        ax.set_title(f"moment {name} (t = {group['time [s]'].iloc[0]:.0f} s)")
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("frequency [Hz]")
    for ax in axes[:, 0]:
        ax.set_ylabel("gain [dB rel. 1 rad/s^2 per N m]")
    axes.flat[0].legend(loc="lower left", fontsize=8)
    fig.suptitle("T_ext{1} -> wdot{1} at the six moments (paper Fig. sigma_plot)")
    fig.tight_layout()
    files["sigma_moments"] = _save(
        fig, out / "sigma_moments.png", _write(sigma, out / "sigma_moments.csv")
    )

    # -- Fig. sigma_plot_springmass
    sweeps = docking_sweeps_data(timeline, frequencies)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8), sharey=True)
    titles = {
        "a": "(a) phase 7: arm docks (SM1 swept, SM2 open)",
        "b": "(b) phase 8: target docks (SM2 swept, SM1 rigid)",
        "c": "(c) phase 8: arm releases (SM1 swept, SM2 rigid)",
    }
    cmap = plt.get_cmap("viridis")
    for ax, (panel, group) in zip(axes, sweeps.groupby("panel", sort=True), strict=True):
        values = np.sort(group["stiffness [N/m or N m/rad]"].unique())
        for k, value in enumerate(values):
            curve = group[group["stiffness [N/m or N m/rad]"] == value]
            ax.semilogx(
                curve["frequency [Hz]"],
                curve["gain [dB]"],
                color=cmap(k / max(1, len(values) - 1)),
                lw=1.0,
                label=f"K = {value:g}",
            )
        ax.set_title(titles[panel], fontsize=10)
        ax.set_xlabel("frequency [Hz]")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("|T_ext,y -> wdot_y| [dB rel. 1 rad/s^2 per N m]")
    axes[0].legend(fontsize=7, title="stiffness [N/m, N m/rad]\ndamping 100", title_fontsize=7)
    fig.tight_layout()
    files["docking_sweeps"] = _save(
        fig, out / "docking_sweeps.png", _write(sweeps, out / "docking_sweeps.csv")
    )

    # -- Fig. inertias
    inertias = inertia_history_data(model, timeline, times)
    fig, (ax_moments, ax_products) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    for key in ("Jxx", "Jyy", "Jzz"):
        ax_moments.plot(inertias["time [s]"], inertias[f"{key} [kg m^2]"], label=key)
    for key in ("Jxy", "Jxz", "Jyz"):
        ax_products.plot(inertias["time [s]"], inertias[f"{key} [kg m^2]"], label=key)
    mission = timeline.scenario.mission
    for ax in (ax_moments, ax_products):
        for t, label in (
            (mission.first_docking_time, "1st docking"),
            (mission.second_docking_time, "2nd docking"),
            (mission.tilt_start_time, "arrays tilt"),
        ):
            ax.axvline(t, color="gray", ls="--", lw=0.8)
            ax.text(t, 1.0, f" {label}", transform=ax.get_xaxis_transform(), fontsize=8, va="top")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    ax_moments.set_ylabel("moments of inertia at G1 [kg m^2]")
    ax_products.set_ylabel("inertia tensor off-diagonal [kg m^2]")
    ax_products.set_xlabel("mission time [s]")
    fig.suptitle("Inertia tensor of the system at G1 in R_RH1 (paper Fig. inertias)")
    fig.tight_layout()
    files["inertias"] = _save(fig, out / "inertias.png", _write(inertias, out / "inertias.csv"))

    # -- Fig. surf
    surface = surface_data(model, timeline, times, frequencies)
    frame = pd.DataFrame(
        surface, index=pd.Index(times, name="time [s]"), columns=[f"{f:.6g}" for f in frequencies]
    )
    frame.columns.name = "frequency [Hz]"
    data_path = out / "surface.parquet"
    frame.to_parquet(data_path)
    fig = plt.figure(figsize=(15, 6.2))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    tt, ff = np.meshgrid(times, np.log10(frequencies), indexing="ij")
    ax.plot_surface(
        tt,
        ff,
        surface,
        cmap="viridis",
        linewidth=0,
        antialiased=False,
        rcount=min(n_times, 165),
        ccount=min(n_frequencies, 250),
    )
    ax.set_xlabel("mission time [s]")
    ax.set_ylabel("log10(frequency / 1 Hz)")
    ax.set_zlabel("gain [dB]")
    ax.view_init(elev=28, azim=-125)
    ax.set_title("3-D view")
    ax_map = fig.add_subplot(1, 2, 2)
    mesh = ax_map.pcolormesh(times, frequencies, surface.T, shading="auto", cmap="viridis")
    ax_map.set_yscale("log")
    ax_map.set_xlabel("mission time [s]")
    ax_map.set_ylabel("frequency [Hz]")
    for t in (mission.first_docking_time, mission.second_docking_time, mission.tilt_start_time):
        ax_map.axvline(t, color="white", ls="--", lw=0.8)
    fig.colorbar(mesh, ax=ax_map, label="|T_ext,x -> phi_x| [dB rel. 1 rad/(N m)]")
    ax_map.set_title("map (dashed: 1st docking, 2nd docking, arrays tilt)")
    fig.suptitle("T_ext{1} -> phi{1} (nominal) over the mission (paper Fig. surf)")
    fig.tight_layout()
    files["surface"] = _save(fig, out / "surface.png", data_path)
    return FigureFiles(files)


def _save(fig, path: Path, data_path: Path) -> tuple[Path, Path]:
    """Save ``fig`` as ``path`` (PNG), close it; ``(path, data_path)`` for the file table."""
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path, data_path
