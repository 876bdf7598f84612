"""``hgrender regress SUITE`` (local regression check for CI) and ``hgrender scheduler`` (the service's
regression scheduler as its own process).

``regress`` runs a suite file (JSON, or YAML for ``.yaml``/``.yml``; the format of
``hgcore.regression.models.Suite``, see docs/regression.md) in one of two modes:

* locally (default, no service needed): renders every scene with ``worker.render.chunks.render_scene`` and
  compares it with its baseline in ``--baseline DIR`` (``DIR/<scene>/image.exr``, ``variance.exr``,
  ``summary.json``) using the service's noise-aware metrics; ``--update-baseline`` then stores the new renders
  as the baselines;
* against a running service (``--url``; the token from ``--token``, ``HGRENDER_TOKEN`` or
  ``<data dir>/admin.token``): ``POST /v1/runs`` with the suite, waits for the run and uses the server's
  baselines; ``--update-baseline`` then promotes the run (``POST /v1/baselines``).

Both print a table, optionally write JUnit XML (``--junit FILE``, one test case per scene) and exit 1 if a
scene failed or could not be compared, 0 otherwise (2 for an invalid suite or a service error).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from hgcore.artifacts.exr import ArtifactFormatError
from hgcore.artifacts.layout import IMAGE_EXR
from hgcore.errors import InputError
from hgrender.cli import CliError, read_json_file
from hgrender.cli.connection import ServiceTarget, add_client_options


def register(subparsers: argparse._SubParsersAction) -> None:
    regress = subparsers.add_parser(
        "regress", help="render a regression suite locally and compare with baselines"
    )
    regress.add_argument("suite", type=Path, help="suite file (.json, .yaml, .yml)")
    regress.add_argument(
        "--baseline", type=Path, default=None, help="baseline directory (default: <suite dir>/baselines)"
    )
    regress.add_argument("--update-baseline", action="store_true", help="store the new renders as baselines")
    regress.add_argument("--junit", type=Path, default=None, help="write a JUnit XML report here")
    regress.add_argument("--seed", type=int, default=None, help="base seed (default: random)")
    regress.add_argument("--work-dir", type=Path, default=None, help="keep the renders here")
    add_client_options(regress, url_default_help="run on the service at this URL instead of locally")
    regress.add_argument("--timeout-s", type=float, default=3600.0, help="longest wait for a service run")
    regress.set_defaults(handler=regress_command)

    scheduler = subparsers.add_parser("scheduler", help="run the regression scheduler against REDIS_URL")
    scheduler.add_argument("--name", default=None, help="scheduler name (default: random)")
    scheduler.set_defaults(handler=scheduler_command)


def load_suite(path: Path) -> Any:
    """The suite file parsed and validated (``hgcore.regression.models.Suite``)."""
    from pydantic import ValidationError

    from hgcore.regression.models import Suite

    if not path.is_file():
        raise CliError(f"suite: {path} is not a file")
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        try:
            data = yaml.safe_load(path.read_text())
        except yaml.YAMLError as error:
            raise CliError(f"suite: {path}: not valid YAML: {error}".replace("\n", " ")) from None
    else:
        data = read_json_file(path, "suite")
    try:
        return Suite.model_validate(data)
    except ValidationError as error:
        problems = [
            f"suite: {'.'.join(str(part) for part in item['loc']) or '/'}: {item['msg']}"
            for item in error.errors()
        ]
        raise CliError("\n".join(problems)) from None


def _copy_outputs(source: Path, destination: Path) -> None:
    from hgcore.regression.store import BASELINE_FILES

    destination.mkdir(parents=True, exist_ok=True)
    for name in BASELINE_FILES:
        temporary = destination / f".{name}.tmp"
        shutil.copyfile(source / name, temporary)
        os.replace(temporary, destination / name)


def run_suite(
    suite: Any, baseline_dir: Path, work_dir: Path, seed: int, update_baseline: bool
) -> list[dict[str, Any]]:
    """Render, compare and (optionally) update the baselines; one result dict per scene."""
    from hgcore.regression.images import load_render_outputs
    from hgcore.regression.metrics import compare_renders
    from hgcore.settings import Settings
    from service.regression.runs import resolve_scene
    from worker.mitsuba_setup import configure_mitsuba

    settings = Settings()
    configure_mitsuba(settings.variant, settings.render_threads)
    from worker.render.chunks import render_scene

    results = []
    for entry in suite.scenes:
        current_dir = work_dir / entry.key
        result: dict[str, Any] = {"scene": entry.key, "verdict": "error", "reasons": [], "metrics": {}}
        try:
            render_scene(resolve_scene(entry, seed, limits=settings), current_dir, limits=settings)
            baseline = baseline_dir / entry.key
            if (baseline / IMAGE_EXR).is_file():
                comparison = compare_renders(
                    entry.key,
                    load_render_outputs(baseline),
                    load_render_outputs(current_dir),
                    suite.thresholds_for(entry),
                )
                result.update(
                    verdict=comparison.verdict, reasons=comparison.reasons, metrics=comparison.metrics
                )
            elif update_baseline:
                result.update(verdict="pass", reasons=[], metrics={"baseline_created": True})
            else:
                result["reasons"] = [f"{entry.key}: no baseline in {baseline} (run with --update-baseline)"]
            if update_baseline:
                _copy_outputs(current_dir, baseline)
        except (InputError, ArtifactFormatError) as error:  # a bad scene or render outputs; bugs raise
            result["reasons"] = [f"{entry.key}: {error}"]
        results.append(result)
    return results


def format_table(results: list[dict[str, Any]]) -> str:
    """A fixed-width table: scene, verdict, worst band rel. RMSE, ΔE00 p95, worst coherence drift, reason."""
    header = f"{'scene':<28} {'verdict':<7} {'rel_rmse':>9} {'dE00_p95':>9} {'coh_drift':>10}  reason"
    lines = [header, "-" * len(header)]
    for result in results:
        metrics = result["metrics"]
        drift = [abs(v["median_rel_change"]) for v in metrics.get("coherence", {}).values()]
        rel_rmse = metrics.get("rel_rmse_max")
        delta_e = metrics.get("delta_e00", {}).get("p95")
        lines.append(
            f"{result['scene']:<28} {result['verdict']:<7} "
            f"{'' if rel_rmse is None else f'{rel_rmse:.4f}':>9} "
            f"{'' if delta_e is None else f'{delta_e:.3f}':>9} "
            f"{'' if not drift else f'{max(drift):.4f}':>10}  "
            f"{'; '.join(result['reasons'])}"
        )
    return "\n".join(lines)


def junit_xml(suite_name: str, results: list[dict[str, Any]]) -> bytes:
    """JUnit XML: a ``testcase`` per scene, with ``<failure>`` if it failed, ``<error>`` if not compared."""
    failures = sum(1 for r in results if r["verdict"] == "fail")
    errors = sum(1 for r in results if r["verdict"] == "error")
    testsuite = ET.Element(
        "testsuite", name=suite_name, tests=str(len(results)), failures=str(failures), errors=str(errors)
    )
    for result in results:
        case = ET.SubElement(
            testsuite, "testcase", classname=f"hgrender.regress.{suite_name}", name=result["scene"]
        )
        if result["verdict"] in ("fail", "error"):
            tag = "failure" if result["verdict"] == "fail" else "error"
            element = ET.SubElement(case, tag, message="; ".join(result["reasons"]))
            element.text = json.dumps(result["metrics"], indent=1, default=float)
    return ET.tostring(ET.ElementTree(testsuite).getroot(), encoding="utf-8", xml_declaration=True)


def run_on_service(
    args: argparse.Namespace, suite: Any, poll_interval_s: float = 1.0
) -> list[dict[str, Any]]:
    """``POST /v1/runs``, wait until the run ends, optionally promote it; one result dict per scene."""
    target = ServiceTarget.from_args(args)
    with target.reporting(), target.client() as client:
        run = client._json("POST", "/v1/runs", json={"suite": suite.model_dump(mode="json")})
        deadline = time.monotonic() + args.timeout_s
        while run["status"] == "running":
            if time.monotonic() > deadline:
                raise CliError(f"timeout_s: run {run['id']} still running after {args.timeout_s} s")
            time.sleep(poll_interval_s)
            run = client._json("GET", f"/v1/runs/{run['id']}")
        if args.update_baseline:
            client._json("POST", "/v1/baselines", json={"run_id": run["id"]})
    print(f"run {run['id']}: {run['status']}", file=sys.stderr)
    return [
        {"scene": r["scene"], "verdict": r["verdict"], "reasons": r["reasons"], "metrics": r["metrics"]}
        for r in run["scenes"]
    ]


def regress_command(args: argparse.Namespace) -> int:
    suite = load_suite(args.suite)
    if args.url is not None:
        if args.baseline is not None or args.seed is not None or args.work_dir is not None:
            raise CliError("url: --baseline, --seed and --work-dir apply to local runs only")
        results = run_on_service(args, suite)
    else:
        baseline_dir = args.baseline if args.baseline is not None else args.suite.parent / "baselines"
        seed = args.seed if args.seed is not None else int.from_bytes(os.urandom(4), "little") & 0x7FFFFFFF
        with tempfile.TemporaryDirectory(prefix="hgrender-regress-") as tmp:
            work_dir = args.work_dir if args.work_dir is not None else Path(tmp)
            results = run_suite(suite, baseline_dir, work_dir, seed, args.update_baseline)
    print(format_table(results))
    if args.junit is not None:
        args.junit.parent.mkdir(parents=True, exist_ok=True)
        temporary = args.junit.with_name(f".{args.junit.name}.tmp")
        temporary.write_bytes(junit_xml(args.suite.stem, results))
        os.replace(temporary, args.junit)
    failed = [r for r in results if r["verdict"] != "pass"]
    print(f"{len(results) - len(failed)} of {len(results)} scenes passed", file=sys.stderr)
    return 1 if failed else 0


def scheduler_command(args: argparse.Namespace) -> int:
    import logging

    from hgcore.settings import Settings
    from service.regression.scheduler import RegressionScheduler

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    scheduler = RegressionScheduler(Settings(), name=args.name)
    signal.signal(signal.SIGTERM, lambda *_: scheduler.stop_event.set())
    try:
        scheduler.run()
    except KeyboardInterrupt:
        scheduler.stop_event.set()
    return 0
