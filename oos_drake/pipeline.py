"""The main job, ``oos run``: model -> controller -> analysis -> confirmation of the worst cases
on the Drake twin -> mu-guided campaign -> report.

Each stage writes one folder under ``--out``. A stage is skipped when its folder holds a stamp
(``stage.json``) whose key matches the current inputs: the key hashes the scenario data file, the
source code of the packages the stage depends on, the stage options and the keys of the stages it
reads. A stage is computed in a temporary folder that replaces the old one only when it succeeds,
so an interrupted ``oos run`` never leaves a half-written stage behind; the campaign stage instead
resumes (no finished run is lost or repeated).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path

from oos_drake import __version__
from oos_drake.resources import package_path

PACKAGE_ROOT = package_path("oos_drake")
DEFAULT_CAMPAIGN = package_path("oos_drake.campaign", "specs", "paper.toml")
STAMP = "stage.json"


def _digest(*parts: str | bytes) -> str:
    digest = hashlib.sha256()
    for part in parts:
        digest.update(part if isinstance(part, bytes) else part.encode())
        digest.update(b"\0")
    return digest.hexdigest()


def source_key(*packages: str) -> str:
    """Hash of the scenario data file, the package's top-level modules (``blas.py``,
    ``processes.py``, ... which every package may use) and the sources of ``packages``
    (``oos_drake.<name>``)."""
    files = [PACKAGE_ROOT / "scenario" / "data" / "paper.toml"]
    files += sorted(PACKAGE_ROOT.glob("*.py"))
    for package in packages:
        files += sorted((PACKAGE_ROOT / package).rglob("*.py"))
    return _digest(__version__, *(f.read_bytes() for f in files))


def _stage_done(folder: Path, key: str) -> bool:
    stamp = folder / STAMP
    return stamp.is_file() and json.loads(stamp.read_text()).get("key") == key


def run_stage(
    name: str,
    folder: Path,
    key: str,
    work: Callable[[Path], None],
    timings: dict[str, float | None] | None = None,
) -> bool:
    """Run ``work(tmp_folder)`` unless ``folder`` is stamped with ``key``; True if it ran.

    ``timings[name]`` receives the stage's wall time in seconds, or None when it was skipped.
    """
    timings = {} if timings is None else timings
    if _stage_done(folder, key):
        print(f"[oos run] {name}: up to date in {folder} (skipped)")
        timings[name] = None
        return False
    print(f"[oos run] {name} -> {folder}")
    start = time.perf_counter()
    tmp = folder.with_name(folder.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    work(tmp)
    (tmp / STAMP).write_text(
        json.dumps({"key": key, "stage": name, "seconds": time.perf_counter() - start}) + "\n"
    )
    shutil.rmtree(folder, ignore_errors=True)
    tmp.rename(folder)
    timings[name] = time.perf_counter() - start
    print(f"[oos run] {name}: done in {timings[name]:.1f} s")
    return True


def _oos(*argv: str) -> None:
    """Run one ``oos`` command in this process; a non-zero status stops the pipeline."""
    from oos_drake.cli import main

    status = main([str(a) for a in argv])
    if status:
        raise SystemExit(status)


def run_pipeline(args: argparse.Namespace) -> int:
    """Run every stage of the main job into ``args.out``; returns the exit status."""
    campaign_spec = Path(args.campaign)
    if not campaign_spec.is_file():
        raise ValueError(f"campaign spec {campaign_spec}: file not found")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float | None] = {}
    start = time.perf_counter()
    quick = ["--configurations", "40"] if args.quick else []

    model_key = source_key("lfr", "titop", "scenario")
    run_stage(
        "model",
        out / "model",
        model_key,
        lambda d: (_oos("model", "info"), _oos("model", "figures", "--out", d)),
        timings,
    )

    multibody_key = _digest(model_key, source_key("multibody"))
    run_stage("validate", out / "validate", multibody_key, _validate, timings)

    controller_key = _digest(model_key, source_key("control", "robust"), *quick)
    run_stage(
        "controller",
        out / "controller",
        controller_key,
        lambda d: _oos("synth", "--out", d, *quick),
        timings,
    )
    controller = out / "controller" / "controller.json"

    analysis_key = _digest(controller_key, source_key("analysis", "robust"), *quick)
    run_stage(
        "analysis",
        out / "analysis",
        analysis_key,
        lambda d: _oos(
            "analyze", "--controller", controller, "--out", d, "--workers", args.workers, *quick
        ),
        timings,
    )

    confirm_key = _digest(analysis_key, multibody_key)  # analysis_key covers analysis/ and robust/
    run_stage(
        "confirm",
        out / "confirm",
        confirm_key,
        lambda d: _oos(
            "confirm",
            "--analysis",
            out / "analysis",
            "--controller",
            controller,
            "--out",
            d,
            "--workers",
            args.workers,
        ),
        timings,
    )

    campaign_key = _digest(
        analysis_key, multibody_key, source_key("campaign"), campaign_spec.read_bytes()
    )
    campaign = out / f"campaign-{campaign_key[:10]}"
    campaign_start = time.perf_counter()
    if (campaign / "spec.toml").is_file():
        print(f"[oos run] campaign: resuming {campaign}")
        _oos("campaign", "resume", campaign, "--workers", args.workers)
    else:
        shutil.rmtree(campaign, ignore_errors=True)
        print(f"[oos run] campaign -> {campaign}")
        _oos(
            "campaign",
            "run",
            campaign_spec,
            "--out",
            campaign,
            "--workers",
            args.workers,
            "--worst-cases",
            out / "analysis" / "worst_cases.parquet",
            "--simulator-option",
            f"controller={controller.resolve()}",
        )
    _oos("campaign", "report", campaign)
    timings["campaign + report"] = time.perf_counter() - campaign_start
    total = time.perf_counter() - start
    (out / "timings.json").write_text(
        json.dumps({"stages_s": timings, "total_s": total}, indent=1) + "\n"
    )

    print("\n[oos run] wall time per stage:")
    for name, seconds in timings.items():
        shown = "skipped (up to date)" if seconds is None else f"{seconds:8.1f} s"
        print(f"  {name:28s} {shown}")
    print(f"  {'total':28s} {total:8.1f} s")
    print("\n[oos run] finished. Where to look:")
    for label, path in (
        ("model figures", out / "model"),
        ("Drake vs TITOP validation", out / "validate" / "validate.txt"),
        ("controller", controller),
        ("robust analysis", out / "analysis"),
        ("worst cases on the Drake twin", out / "confirm" / "confirmation.parquet"),
        ("campaign results", campaign / "runs.parquet"),
        ("campaign report", campaign / "report"),
    ):
        print(f"  {label:28s} {path}")
    return 0


def _validate(folder: Path) -> None:
    """``oos validate`` with its table saved next to the other results."""
    import contextlib
    import io

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        from oos_drake.cli import main

        status = main(["validate"])
    (folder / "validate.txt").write_text(buffer.getvalue())
    print(buffer.getvalue())
    if status:
        raise SystemExit(status)


def register(subparsers) -> None:
    """Add ``oos run`` (the main job of ``make run``)."""
    parser = subparsers.add_parser(
        "run",
        help="the main job: model, Drake validation, controller, analysis, campaign, report",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--out", default="out", help="output folder (default: out)")
    parser.add_argument(
        "--campaign", default=str(DEFAULT_CAMPAIGN), help="campaign spec (default: paper.toml)"
    )
    parser.add_argument(
        "--workers", type=int, default=2, help="worker processes of the analysis and the campaign"
    )
    parser.add_argument(
        "--quick", action="store_true", help="40 configurations instead of the paper's grids"
    )
    parser.set_defaults(func=run_pipeline)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(prog="oos")
    register(parser.add_subparsers(dest="command"))
    sys.exit(run_pipeline(parser.parse_args(["run", *sys.argv[1:]])))
