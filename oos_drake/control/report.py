"""Synthesis outputs: controller JSON, closed-loop model array (.npz, .mat), per-model tables.

Files written by :func:`write_synthesis` in ``out_dir``:

``controller.json``
    Gains with units, gamma (and the baseline's), the active models, the configuration list,
    the worst cases found, a SHA-256 of the model data, the design weights and options.
``closed_loop.npz`` / ``closed_loop.mat``
    ``A, B, C, D`` of every closed loop ``d -> e`` of the final model set, channel names,
    configuration index and parameter values. The model index is the leading dimension in the
    ``.npz`` (``A[k]``) and the last one in the ``.mat`` (MATLAB's ``A(:, :, k)``).
``models.parquet`` / ``models.csv``
    One row per model: configuration, parameters, gamma_i, peak frequency, flags.
``runs.csv``, ``worst_cases.csv``
    Optimizer runs and worst-case searches.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from oos_drake.control.interconnection import DISTURBANCES, ERRORS, weighted_interconnection
from oos_drake.control.plants import PlantArray
from oos_drake.control.synthesis import SynthesisOptions, SynthesisResult
from oos_drake.files import atomic_write_bytes
from oos_drake.lfr.matfile import write_mat


def _json_ready(value):
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_ready(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None if np.isnan(value) else ("inf" if value > 0 else "-inf")
    return value


def controller_record(result: SynthesisResult, plants: PlantArray, options=None) -> dict:
    """Return the JSON-ready description of a synthesized controller."""
    table = result.models
    active = table[table["active"]]
    return _json_ready(
        {
            "controller": {
                "structure": "u_K = K y, y = [phi_ref - phi_sst; w_ref - w_gyro], u = F_ro u_K",
                "K_p": {"value": result.K[:, :3], "unit": "N m/rad"},
                "K_d": {"value": result.K[:, 3:], "unit": "N m s/rad"},
                "K_p_baseline": {"value": result.K_start[:, :3], "unit": "N m/rad"},
                "K_d_baseline": {"value": result.K_start[:, 3:], "unit": "N m s/rad"},
                "rolloff": {
                    "type": "butterworth",
                    "order": result.spec.rolloff_order,
                    "cutoff_hz": result.spec.rolloff_cutoff_hz,
                },
            },
            "structure": "static",
            "status": "ok",
            "goals": [
                {
                    "name": "weighted gain d->e",
                    "kind": "soft",
                    "value": result.gamma,
                    "met": bool(result.gamma < 1.0),
                    "details": {"hinf_norm": result.gamma},
                }
            ],
            "gamma": result.gamma,
            "gamma_baseline": result.gamma_start,
            "requirement_met": bool(result.gamma < 1.0),
            "active_models": active[
                ["config", *result.parameter_names, "gamma [-]", "peak frequency [Hz]"]
            ].to_dict(orient="records"),
            "configurations": plants.configurations.to_dict(orient="list"),
            "uncertain_parameters": [asdict(p) for p in plants.parameters],
            "worst_cases": result.worst_cases.to_dict(orient="records"),
            "model_source": plants.source,
            "model_statistics": plants.statistics() if plants.statistics else None,
            "model_sha256": plants.fingerprint(),
            "design_specification": result.spec.to_dict(),
            "options": asdict(options) if options is not None else None,
            "wall_time_s": result.wall_time_s,
        }
    )


def closed_loop_array(result: SynthesisResult, plants: PlantArray):
    """Closed loops ``d -> e`` of the final model set (a batched ``BatchedStateSpace``)."""
    table = result.models
    values = table[list(result.parameter_names)].to_numpy(dtype=float).reshape(len(table), -1)
    plant = plants.evaluate(table["config"].to_numpy(), values)
    return weighted_interconnection(plant, result.spec).close(result.K)


def write_synthesis(
    out_dir,
    result: SynthesisResult,
    plants: PlantArray,
    options: SynthesisOptions | None = None,
    *,
    scenario_record: dict | None = None,
) -> dict[str, Path]:
    """Write every synthesis output in ``out_dir`` (created); return name -> path.

    ``scenario_record`` (:func:`oos_drake.scenario.data.scenario_record`) is recorded in
    ``controller.json`` as ``"scenario"``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    record = controller_record(result, plants, options)
    paths["controller"] = write_controller(out, record, scenario_record=scenario_record)
    M = closed_loop_array(result, plants)
    table = result.models
    arrays = {
        "A": M.A,
        "B": M.B,
        "C": M.C,
        "D": M.D,
        "K": result.K,
        "config": table["config"].to_numpy(),
        "parameter_values": table[list(result.parameter_names)].to_numpy(dtype=float),
        "gamma": table["gamma [-]"].to_numpy(),
        "omega_peak_rad_s": 2 * np.pi * table["peak frequency [Hz]"].to_numpy(),
    }
    paths.update(write_closed_loops(out, arrays, result.parameter_names))
    tables = {
        "parquet": ("models.parquet", table.to_parquet),
        "csv": ("models.csv", table.to_csv),
        "runs": ("runs.csv", result.runs.to_csv),
        "worst_cases": ("worst_cases.csv", result.worst_cases.to_csv),
    }
    for key, (name, write) in tables.items():
        paths[key] = atomic_write_bytes(out / name, lambda s, write=write: write(s, index=False))
    return paths


def write_closed_loops(out_dir, arrays: dict, parameter_names) -> dict[str, Path]:
    """Write ``closed_loop.npz`` and ``closed_loop.mat`` (``arrays`` and the channel and
    parameter names) in ``out_dir``; return ``{"npz": path, "mat": path}``."""
    out = Path(out_dir)
    names = {
        "inputs": np.array(DISTURBANCES),
        "outputs": np.array(ERRORS),
        "parameter_names": np.array(parameter_names, dtype=str),
    }
    npz = out / "closed_loop.npz"
    atomic_write_bytes(npz, lambda stream: np.savez_compressed(stream, **arrays, **names))
    mat = write_mat(
        out / "closed_loop.mat",
        {**arrays, **{key: np.array(value, dtype=object) for key, value in names.items()}},
        matrices="ABCD",
    )
    return {"npz": npz, "mat": mat}


def tuning_closed_loop_arrays(result, plants: PlantArray, loops) -> dict:
    """``closed_loop.npz``'s arrays for a tuned controller (the keys of
    :func:`write_synthesis`'s): ``A, B, C, D`` of the loops ``d -> e`` of every configuration
    (``loops``: :func:`~oos_drake.control.requirements.performance_closed_loops`, discrete
    when ``sampling_time_s`` > 0), ``config``, ``parameter_values`` (nominal), ``gamma``
    (each loop's certified H-infinity norm; for a discrete loop, of its bilinear image
    ``z = (1 + s) / (1 - s)``, the same norm), ``omega_peak_rad_s`` (its peak frequency),
    ``sampling_time_s``, and ``K`` [N m/rad, N m s/rad] when the controller is the static
    3x6 gain, else the whole controller's ``controller_A`` ... ``controller_D``."""
    from oos_drake.robust.peak_gain import peak_gain

    A, B, C, D = (np.asarray(M, dtype=float) for M in (loops.A, loops.B, loops.C, loops.D))
    ts = float(result.sampling_time)
    if ts > 0:  # the bilinear image: same H-infinity norm, frequency tan(w T / 2)
        eye = np.eye(A.shape[-1])
        F = np.linalg.inv(A + eye)
        peaks = peak_gain(
            F @ (A - eye), np.sqrt(2) * F @ B, np.sqrt(2) * C @ F, D - C @ F @ B, certify=True
        )
        omega = 2 * np.arctan(peaks.omega) / ts
    else:
        peaks = peak_gain(A, B, C, D, certify=True)
        omega = peaks.omega
    N = plants.size
    arrays = {
        "A": A,
        "B": B,
        "C": C,
        "D": D,
        "config": np.arange(N),
        "parameter_values": np.broadcast_to(
            plants.nominal_values, (N, len(plants.parameters))
        ).copy(),
        "gamma": np.asarray(peaks.gamma, dtype=float),
        "omega_peak_rad_s": np.asarray(omega, dtype=float),
        "sampling_time_s": np.array(ts),
    }
    if "K" in result.parameters and set(result.parameters["K"]) == {"D"}:
        arrays["K"] = np.asarray(result.parameters["K"]["D"], dtype=float)
    else:
        sys = result.controller
        arrays |= {f"controller_{m}": np.asarray(getattr(sys, m), float) for m in "ABCD"}
    return arrays


def tuning_record(result, requirements, K0, plants: PlantArray, spec, options=None) -> dict:
    """JSON-ready description of a controller tuned to the ``[control]`` requirements.

    Parameters
    ----------
    result : oos_drake.control.systune.TuningResult
    requirements : oos_drake.scenario.data.ControlRequirements
    K0 : numpy.ndarray, shape (3, 6)
        Baseline (start) gain [N m/rad, N m s/rad].
    plants : PlantArray
    spec : DesignSpecification
        The specification the goals were evaluated with (at ``rate_hz`` when given: the
        discrete design).
    options : SystuneOptions, optional

    ``status`` is the tuning result's: ``"infeasible"`` means a hard goal is NOT met and the
    values recorded are the best reached. Each goal's ``value`` and ``per_model`` are over
    every configuration of ``plants`` (``models_checked`` of them), the optimizer's final
    working set is ``working_set`` (configuration indices), ``rounds`` its growth.
    """
    controller = {
        "structure": requirements.structure,
        "parameters": {
            block: {name: np.asarray(value) for name, value in values.items()}
            for block, values in result.parameters.items()
        },
        "rolloff": {
            "type": "butterworth",
            "order": spec.rolloff_order,
            "cutoff_hz": spec.rolloff_cutoff_hz,
        },
    }
    sys = result.controller  # the whole controller, read by oos_drake.analysis.controller
    controller["state_space"] = {
        "A": sys.A,
        "B": sys.B,
        "C": sys.C,
        "D": sys.D,
        "inputs": list(sys.input_labels),
        "outputs": list(sys.output_labels),
        "sampling_time_s": float(result.sampling_time),
    }
    if requirements.structure == "static":
        K = np.asarray(result.parameters["K"]["D"], dtype=float)
        controller.update(
            K_p={"value": K[:, :3], "unit": "N m/rad"},
            K_d={"value": K[:, 3:], "unit": "N m s/rad"},
            K_p_baseline={"value": K0[:, :3], "unit": "N m/rad"},
            K_d_baseline={"value": K0[:, 3:], "unit": "N m s/rad"},
        )
    weighted = result.goals[0]
    return _json_ready(
        {
            "controller": controller,
            "structure": requirements.structure,
            "status": result.status,
            "goals": [
                {
                    "name": g.name,
                    "kind": g.kind,
                    "value": g.value,
                    "met": g.met,
                    "details": dict(g.details),
                    "per_model": g.per_model,
                }
                for g in result.goals
            ],
            "requirements": {
                "gain_margin_db": requirements.gain_margin_db,
                "phase_margin_deg": requirements.phase_margin_deg,
                "loop_opening": requirements.loop_opening,
                "min_damping": requirements.min_damping,
                "order": requirements.order,
                "rate_hz": requirements.rate_hz,
                "loop": "sampled (rational hold model)" if spec.sampled else "continuous",
            },
            "gamma": weighted.value,
            "requirement_met": bool(weighted.value < 1.0 and result.status == "ok"),
            "runs": list(result.runs),
            # every goal's value and per_model are over all the configurations below
            "models_checked": result.models_checked,
            "working_set": list(result.working_set),
            "rounds": list(result.rounds),
            "verification": verification_record(result, options),
            "configurations": plants.configurations.to_dict(orient="list"),
            "model_source": plants.source,
            "model_sha256": plants.fingerprint(),
            "design_specification": spec.to_dict(),
            "options": asdict(options) if options is not None else None,
        }
    )


def verification_record(result, options=None) -> dict:
    """Where the goals of a :class:`~oos_drake.control.systune.TuningResult` were verified:
    the configurations of the array (``configurations_checked``, the working set's check) and
    those between them (``configurations_between``, checked after the tuning only), and per
    goal its worst value over all of them (for margins: the smallest disk margin and the
    gain and phase margins it implies). Nothing is claimed between these configurations;
    ``hard_surplus`` is the relative surplus the hard goals were tuned with."""
    goals = []
    for checked in result.goals:
        between = [g for g in result.verified if g.name == checked.name]
        worst = max([checked, *between], key=lambda g: g.value)
        goals.append(
            {
                "name": checked.name,
                "kind": checked.kind,
                "value": worst.value,
                "met": worst.met,
                "where": "between" if between and worst is between[0] else "checked",
                "details": dict(worst.details),
                "value_checked": checked.value,
                "value_between": between[0].value if between else None,
            }
        )
    return {
        "configurations_checked": result.models_checked,
        "configurations_between": result.models_verified - result.models_checked,
        "configurations_verified": result.models_verified,
        "hard_surplus": getattr(options, "hard_surplus", None),
        "goals": goals,
    }


def write_controller(out_dir, record: dict, *, scenario_record: dict | None = None) -> Path:
    """Write ``record`` as ``controller.json`` in ``out_dir`` (created), atomically: the one
    writer of that file (its reader: :func:`oos_drake.control.interconnection.read_controller`).

    ``scenario_record`` (:func:`oos_drake.scenario.data.scenario_record`) is recorded as
    ``"scenario"``. Returns the file's path.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if scenario_record is not None:
        record = {**record, "scenario": _json_ready(scenario_record)}
    text = json.dumps(record, indent=2).encode()
    return atomic_write_bytes(out / "controller.json", lambda s: s.write(text))


def write_tuning(
    out_dir,
    record: dict,
    *,
    scenario_record: dict | None = None,
    loops: dict | None = None,
    parameter_names=(),
) -> dict[str, Path]:
    """Write ``controller.json`` of :func:`tuning_record` in ``out_dir`` and, with ``loops``
    (:func:`tuning_closed_loop_arrays`), ``closed_loop.npz``/``.mat`` as
    :func:`write_synthesis` does; return name -> path."""
    paths = {"controller": write_controller(out_dir, record, scenario_record=scenario_record)}
    if loops is not None:
        paths.update(write_closed_loops(out_dir, loops, parameter_names))
    return paths
