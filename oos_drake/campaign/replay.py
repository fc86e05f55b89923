"""Self-contained HTML 3D replay of one campaign run (``oos campaign replay DIR --case N``).

:func:`replay_case` re-simulates run ``N`` of a campaign exactly as the campaign ran it (same
simulator options, dispersed values, seed and mission window, read back from the campaign
directory), then plays the logged plant states into a Meshcat recording
(:func:`oos_drake.multibody.replay.recording_html`, which also describes what is drawn) and writes
``meshcat.StaticHtml()`` atomically to ``DIR/replay/case_N.html``: one file, no server, that any
browser opens (scene, animation, play/pause and time-scale controls under *Animations*).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from oos_drake.campaign.runner import case_from_plan_row, load_campaign
from oos_drake.files import atomic_write_text
from oos_drake.multibody.replay import default_speed, recording_html

__all__ = ["ReplayResult", "replay_case", "replay_path"]


@dataclass(frozen=True)
class ReplayResult:
    """What :func:`replay_case` wrote.

    Attributes
    ----------
    path : Path
        The HTML file (``DIR/replay/case_N.html``).
    run_id : int
        Replayed run.
    start, end : float
        Simulated window [s] (``end`` is the last logged sample when the run diverged).
    frame_rate : float
        Logged samples per simulated second [Hz] (the simulator's ``log_rate``).
    frames : int
        Frames in the recording (``round((end - start) * frame_rate) + 1``).
    speed : float
        Playback speed (simulated seconds per second of animation) [-].
    status : str
        ``"ok"`` or ``"diverged"`` (the replay shows the run up to the divergence).
    error : str
        Divergence message (empty if ``ok``).
    bytes : int
        Size of the HTML file [B].
    """

    path: Path
    run_id: int
    start: float
    end: float
    frame_rate: float
    frames: int
    speed: float
    status: str
    error: str
    bytes: int


def replay_path(directory: str | Path, run_id: int) -> Path:
    """``DIR/replay/case_N.html``: where the replay of run ``run_id`` goes."""
    return Path(directory) / "replay" / f"case_{int(run_id)}.html"


def _load_case(directory: Path, run_id: int):
    spec, plan = load_campaign(directory)
    matches = plan[plan["run_id"] == int(run_id)]
    if matches.empty:
        raise ValueError(
            f"--case {run_id}: no such run in {directory} (the plan has runs 0..{len(plan) - 1})"
        )
    return spec, case_from_plan_row(spec, matches.iloc[0])


def _mission_simulation(spec):
    from oos_drake.campaign.drake_simulator import DrakeMissionSimulator
    from oos_drake.campaign.simulator import build_simulator

    simulator = build_simulator(spec.simulator)
    if not isinstance(simulator, DrakeMissionSimulator):
        raise ValueError(
            f"simulator {spec.simulator.name!r} has no 3D model to replay (replay needs the Drake "
            "mission simulator oos_drake.campaign.drake_simulator:make_simulator)"
        )
    return simulator.simulation


def replay_case(
    directory: str | Path, run_id: int, *, speed: float | None = None, meshcat=None
) -> ReplayResult:
    """Re-simulate run ``run_id`` of a campaign and write its HTML 3D replay.

    Parameters
    ----------
    directory : str or Path
        Campaign directory (``oos campaign run --out``).
    run_id : int
        Run to replay (``--case``).
    speed : float, optional
        Playback speed [-] (simulated seconds per second of animation; the viewer's *Animations*
        panel can change it further). Default: :func:`default_speed` of the window.
    meshcat : pydrake.geometry.Meshcat, optional
        Visualizer to record into (default: a new one on a free local port, closed after).

    Returns
    -------
    ReplayResult

    Raises
    ------
    ValueError
        Not a campaign directory, unknown run id, a simulator without a 3D model, or a bad
        ``speed``; nothing is written then.
    """
    from oos_drake.multibody.mission_sim import MissionDiverged

    directory = Path(directory)
    if speed is not None and not (
        isinstance(speed, int | float) and math.isfinite(speed) and speed > 0
    ):
        raise ValueError(f"replay speed must be a positive number, got {speed!r}")
    spec, case = _load_case(directory, run_id)
    simulation = _mission_simulation(spec)
    contexts = []  # the run's root context (it holds the logs), given by on_start
    status, error = "ok", ""
    try:
        simulation.run(
            dict(case.values),
            seed=case.seed,
            start=case.window.start,
            end=case.window.end,
            log=False,
            on_start=contexts.append,
            perturbation_frequency_hz=case.frequency,
        )
    except MissionDiverged as exc:
        status, error = "diverged", str(exc)
    if not contexts:
        raise ValueError(f"run {run_id}: the simulation did not start ({error})")
    times, states = simulation.state_log(contexts[-1])
    if times.size == 0:
        raise ValueError(f"run {run_id}: no logged state to replay ({error or 'empty window'})")
    if speed is None:
        speed = default_speed(case.window.end - case.window.start)
    html, frames = recording_html(simulation.handles, times, states, float(speed), meshcat=meshcat)
    path = atomic_write_text(html, replay_path(directory, case.run_id))
    size = len(html.encode("utf-8"))
    return ReplayResult(
        path=path,
        run_id=case.run_id,
        start=float(times[0]),
        end=float(times[-1]),
        frame_rate=float(simulation.options.log_rate),
        frames=frames,
        speed=float(speed),
        status=status,
        error=error,
        bytes=size,
    )
