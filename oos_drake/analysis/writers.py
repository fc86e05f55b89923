"""Files of an :class:`~oos_drake.analysis.results.AnalysisResult`: every table, the whole
perturbations, ``worst_cases.parquet``, the figures and ``summary.json``, each written
atomically (temporary file, then rename). The files are listed in
:mod:`oos_drake.analysis.run`.
"""

from __future__ import annotations

import json
import time as _time
from pathlib import Path

import numpy as np

from oos_drake.analysis.results import AnalysisResult
from oos_drake.files import atomic_write_bytes, atomic_write_parquet, atomic_write_text

#: Tables written but not listed in ``summary.json``'s ``"files"`` (as before the split).
UNLISTED = ("time_signals",)


def write_analysis(result: AnalysisResult, out_dir, *, log=print) -> dict:
    """Write ``result`` in ``out_dir`` (created): tables, perturbations, worst cases, figures
    and ``summary.json``.

    Parameters
    ----------
    result : AnalysisResult
        From :func:`~oos_drake.analysis.run.compute_analysis`.
    out_dir : str or Path
        Output directory.
    log : callable
        Progress messages.

    Returns
    -------
    dict
        The summary written to ``summary.json``: :meth:`AnalysisResult.summary`, the files
        (relative to ``out_dir``) and the timings with the figures' [s].
    """
    from oos_drake.analysis import figures

    start = _time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name, table in result.tables().items():
        path = atomic_write_parquet(table, out / f"{name}.parquet")
        if name not in UNLISTED:
            paths[name] = path
    paths["peak_perturbations"] = write_perturbations(
        out / "peak_perturbations.npz", result.certificates
    )
    paths["worst_cases"] = paths.pop("worst_cases")  # listed after the perturbations, as before
    paths.update(figures.analysis_figures(result, out))
    seconds = _time.perf_counter() - start
    log(f"  [figures: {seconds:.1f} s]")
    summary = result.summary()
    timings = summary["timings_s"]
    timings["figures"] = round(seconds, 2)
    timings["spike resolution, all studies"] = round(result.spike_seconds, 2)
    timings["total"] = round(result.seconds + seconds, 2)
    summary["files"] = {k: Path(v).name for k, v in paths.items()}  # relative to out_dir
    atomic_write_text(summary_json(summary), out / "summary.json")
    return summary


def write_perturbations(path: Path, certificates: dict) -> Path:
    """The whole normalized destabilizing perturbation of every certified peak, for re-checks.

    Keys ``"<study>|<subset>|<block>"`` hold the block's normalized value (a float for a
    ``ureal``, the complex matrix of an ``ultidyn``); ``"<study>|<subset>|model"`` and
    ``"<study>|<subset>|omega [rad/s]"`` the critical model and frequency.

    Parameters
    ----------
    path : Path
        The ``.npz`` file.
    certificates : dict
        Study -> subset -> :class:`~oos_drake.analysis.results.Certificate`.
    """
    arrays = {}
    for study, certs in certificates.items():
        for subset, cert in certs.items():
            arrays[f"{study}|{subset}|model"] = np.int64(cert.model)
            arrays[f"{study}|{subset}|omega [rad/s]"] = np.float64(2 * np.pi * cert.frequency_hz)
            for block, value in cert.normalized.items():
                arrays[f"{study}|{subset}|{block}"] = np.asarray(value)
    return atomic_write_bytes(path, lambda stream: np.savez(stream, **arrays))


def summary_json(summary: dict) -> str:
    """The text of ``summary.json`` (NumPy scalars and arrays as JSON numbers and lists)."""
    return json.dumps(summary, indent=2, default=_json_default)


def _json_default(value):
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.bool_,)):
        return bool(value)
    return str(value)


def write_margins(result, out_dir) -> dict:
    """Write a :class:`~oos_drake.analysis.margins.MarginsResult` in ``out_dir`` (created):
    its tables (``margins.parquet``, ``ray_boundaries.parquet`` with rays), ``margins.png``
    (:func:`~oos_drake.analysis.figures.margins_figure`) and ``summary.json``
    (:meth:`~oos_drake.analysis.margins.MarginsResult.summary`), each atomically.

    Returns
    -------
    dict
        The summary written.
    """
    from oos_drake.analysis.figures import margins_figure

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for name, table in result.tables().items():
        atomic_write_parquet(table, out / f"{name}.parquet")
    rate_hz = result.controller.spec.flight_software_rate_hz
    margins_figure(result.margins, out / "margins.png", rate_hz)
    summary = result.summary()
    atomic_write_text(summary_json(summary), out / "summary.json")
    return summary


def write_confirmation(result, out_dir) -> dict:
    """Write a :class:`~oos_drake.analysis.confirm.ConfirmationResult` in ``out_dir``
    (created): its tables (``confirmation.parquet``, ``confirmation_histories.parquet``,
    ``performance_confirmation.parquet``), one figure per peak with nonlinear runs
    (``confirmation_<study>_<subset>.png``:
    :func:`~oos_drake.analysis.figures.confirmation_figures`) and ``summary.json``
    (:meth:`~oos_drake.analysis.confirm.ConfirmationResult.summary`), each atomically.

    Returns
    -------
    dict
        The summary written.
    """
    from oos_drake.analysis.figures import confirmation_figures

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for name, table in result.tables().items():
        atomic_write_parquet(table, out / f"{name}.parquet")
    confirmation_figures(result, out)
    summary = result.summary()
    atomic_write_text(summary_json(summary), out / "summary.json")
    return summary
