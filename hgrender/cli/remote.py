"""``hgrender submit | status | list | cancel | download | view | token``: talk to a running service.

They find the service and their token as ``hgrender.cli.connection`` describes (``--url`` /
``HGRENDER_URL``, ``--token`` / ``HGRENDER_TOKEN`` / ``<data dir>/admin.token``). A service that is down,
a wrong URL or a rejected token is one line on stderr and exit 2; a rejected scene lists every problem
the API found, one per line, with its JSON pointer or field.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from hgrender.cli import CliError, positive_int, read_json_file
from hgrender.cli.connection import ServiceTarget, add_client_options
from hgrender.cli.progress import ProgressDisplay
from hgrender.cli.render import add_quality_options
from hgrender.cli.tev import TevImage, add_tev_option
from hgrender.client import ApiError

FILM_OVERRIDES: tuple[str, ...] = ("width", "height", "bands")
SEED_MAX = 2**32 - 1


def seed_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, {SEED_MAX}], got {text!r}") from None
    if not 0 <= value <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, {SEED_MAX}], got {text!r}")
    return value


def register(subparsers: argparse._SubParsersAction) -> None:
    client_options = argparse.ArgumentParser(add_help=False)
    add_client_options(client_options)

    submit = subparsers.add_parser("submit", parents=[client_options], help="submit a scene file")
    submit.add_argument("scene", type=Path, help=".json scene, .usda/.usdc/.usdz or a .zip bundle")
    submit.add_argument("--wait", action="store_true", help="follow progress until the job finishes")
    submit.add_argument("--spp", type=positive_int, default=None, help="samples per pixel (scene's own)")
    submit.add_argument("--chunks", type=positive_int, default=None, help="parallel chunks (server's)")
    submit.add_argument("--seed", type=seed_int, default=None, help="base seed (scene's own)")
    submit.add_argument("--width", type=positive_int, default=None, help="film width, px (JSON scenes)")
    submit.add_argument("--height", type=positive_int, default=None, help="film height, px (JSON scenes)")
    submit.add_argument("--bands", type=positive_int, default=None, help="spectral bands (JSON scenes)")
    submit.add_argument("--name", default=None, help="label shown in listings (default: the scene's)")
    submit.add_argument("--priority", choices=("high", "normal", "low"), default="normal", help="queue")
    add_quality_options(submit)
    submit.add_argument(
        "--idempotency-key", default=None, help="repeating a submission with this key returns the first job"
    )
    submit.set_defaults(handler=submit_command)

    status = subparsers.add_parser("status", parents=[client_options], help="show a job")
    status.add_argument("job_id")
    status.set_defaults(handler=status_command)

    listing = subparsers.add_parser("list", parents=[client_options], help="list jobs")
    listing.add_argument(
        "--status", default=None, choices=("queued", "running", "succeeded", "failed", "canceled")
    )
    listing.add_argument("--limit", type=positive_int, default=50)
    listing.set_defaults(handler=list_command)

    cancel = subparsers.add_parser("cancel", parents=[client_options], help="cancel a job")
    cancel.add_argument("job_id")
    cancel.set_defaults(handler=cancel_command)

    download = subparsers.add_parser("download", parents=[client_options], help="download a job's artifacts")
    download.add_argument("job_id")
    download.add_argument("-o", "--output", type=Path, default=None, help="directory (default: ./<job id>)")
    download.set_defaults(handler=download_command)

    view = subparsers.add_parser(
        "view", parents=[client_options], help="stream a job's image into tev, or print its viewer URL"
    )
    view.add_argument("job_id")
    add_tev_option(view, "as chunks finish")
    view.set_defaults(handler=view_command)

    token = subparsers.add_parser("token", help="manage API tokens")
    token_commands = token.add_subparsers(dest="token_command", required=True)
    create = token_commands.add_parser("create", parents=[client_options], help="create a token (admin)")
    create.add_argument("--scopes", default="submit,read", help="comma-separated: submit, read, admin")
    create.add_argument("--owner", required=True)
    create.add_argument("--name", default="")
    create.set_defaults(handler=token_create_command)


# ---- submit --------------------------------------------------------------------------------------------


def scene_submission(path: Path, film_overrides: dict[str, int]) -> dict[str, Any] | Path:
    """What to send for the scene file: a JSON scene as a dict with the film overrides applied (as the
    web form does), a USD file or bundle as the path itself (sent as multipart)."""
    if not path.is_file():
        raise CliError(f"scene: no such file {str(path)!r}")
    if path.suffix.lower() != ".json":
        if film_overrides:
            options = ", ".join(f"--{key}" for key in film_overrides)
            raise CliError(
                f"{next(iter(film_overrides))}: {options} apply to .json scenes only "
                "(a USD stage sets its own film)"
            )
        return path
    scene = read_json_file(path, "scene")
    if not isinstance(scene, dict):
        raise CliError(f"scene: {path}: must be a JSON object, got {type(scene).__name__}")
    if film_overrides:
        film = scene.get("film")
        # A film that is not an object is left as it is: the API names /film in its answer.
        if film is None:
            scene["film"] = dict(film_overrides)
        elif isinstance(film, dict):
            film.update(film_overrides)
    return scene


def submit_command(args: argparse.Namespace) -> int:
    film_overrides = {key: getattr(args, key) for key in FILM_OVERRIDES if getattr(args, key) is not None}
    submission = scene_submission(args.scene, film_overrides)
    target = ServiceTarget.from_args(args)
    with target.reporting(subject=str(args.scene)), target.client() as client:
        created = client.submit(
            submission,
            priority=args.priority,
            spp=args.spp,
            chunks=args.chunks,
            seed=args.seed,
            idempotency_key=args.idempotency_key,
            name=args.name,
            integrator=args.integrator,
            target_rel_error=args.target_rel_error,
            time_budget_s=args.time_budget_s,
            target_quantile=args.target_quantile,
        )
        print(created["id"], flush=True)
        if not args.wait:
            return 0
        final = follow_job(client, created["id"])
    print(json.dumps({k: final.get(k) for k in ("id", "status", "error")}))
    return 0 if final["status"] == "succeeded" else 1


def follow_job(client: Any, job_id: str, on_view: Any = None) -> dict[str, Any]:
    """Wait for the job, showing its progress (status, chunks, ETA) on stderr; ``on_view(view)`` is
    called with the job's state after every event. Returns its final view."""
    state: dict[str, Any] = {}
    with ProgressDisplay(f"job {job_id}") as display:

        def on_event(_event: str, data: dict[str, Any]) -> None:
            state.update(data)  # progress events carry progress/chunks/eta, status events the whole view
            display.update(
                state.get("progress", 0.0),
                state.get("status"),
                state.get("chunks_done"),
                state.get("chunks_total"),
                state.get("eta_s"),
            )
            if on_view is not None:
                on_view(state)

        return client.wait(job_id, on_event=on_event)


# ---- inspect and manage --------------------------------------------------------------------------------


def status_command(args: argparse.Namespace) -> int:
    target = ServiceTarget.from_args(args)
    with target.reporting(), target.client() as client:
        print(json.dumps(client.get(args.job_id), indent=2))
    return 0


def list_command(args: argparse.Namespace) -> int:
    target = ServiceTarget.from_args(args)
    with target.reporting(), target.client() as client:
        page = client.list(status=args.status, limit=args.limit)
    for job in page["items"]:
        label = job.get("name") or ""
        print(f"{job['id']}  {job['status']:<9}  {job['progress']:6.1%}  {job['owner']:<12} {label}")
    print(f"{len(page['items'])} of {page['total']} jobs", file=sys.stderr)
    return 0


def cancel_command(args: argparse.Namespace) -> int:
    target = ServiceTarget.from_args(args)
    with target.reporting(), target.client() as client:
        print(client.cancel(args.job_id)["status"])
    return 0


def download_command(args: argparse.Namespace) -> int:
    out_dir = args.output if args.output is not None else Path(args.job_id)
    target = ServiceTarget.from_args(args)
    with target.reporting(), target.client() as client:
        for path in client.download_all(args.job_id, out_dir):
            print(path)
    return 0


def token_create_command(args: argparse.Namespace) -> int:
    scopes = [s.strip() for s in args.scopes.split(",") if s.strip()]
    target = ServiceTarget.from_args(args)
    with target.reporting(), target.client() as client:
        created = client.create_token(args.owner, scopes, args.name)
    print(created["token"])
    return 0


# ---- view ----------------------------------------------------------------------------------------------


def view_command(args: argparse.Namespace) -> int:
    """Without ``--tev``: print the browser viewer's URL for the job. With it: send the job's image to
    tev, the chunks finished so far while it runs (refreshed as more finish), the final image at the end."""
    target = ServiceTarget.from_args(args)
    if args.tev is None:
        print(f"{target.url}/#/view/{args.job_id}")
        return 0
    # tev first: one that is not running is reported before anything is asked of the service.
    with TevImage(args.tev, f"hgrender {args.job_id}") as tev, target.reporting(), target.client() as client:
        view = client.get(args.job_id)
        shown_chunks = 0

        def show_partial(state: dict[str, Any]) -> None:
            nonlocal shown_chunks
            done = int(state.get("chunks_done") or 0)
            if state.get("status") == "running" and done > shown_chunks:
                try:
                    channels = job_channels(client, args.job_id)
                except ApiError as error:
                    if error.status_code != 409:
                        raise
                    return  # no merged chunk to show yet: a later event (or the final image) shows it
                tev.show(channels)
                shown_chunks = done

        if view["status"] not in ("succeeded", "failed", "canceled"):
            view = follow_job(client, args.job_id, on_view=show_partial)
        if view["status"] != "succeeded":
            reason = view.get("error") or "it has no image"
            raise CliError(f"job_id: job {args.job_id} {view['status']}: {reason}")
        tev.show(job_channels(client, args.job_id))
    print(f"{args.job_id}: sent to tev at {args.tev[0]}:{args.tev[1]}", file=sys.stderr)
    return 0


def job_channels(client: Any, job_id: str) -> dict[str, Any]:
    """The job's image as the viewer's data API serves it (the final ``image.exr``, or for a running job
    the merge of its finished chunks), as ``image.exr``'s channels: name → float32 (H, W)."""
    import numpy as np

    catalogue = client.layers(job_id)
    height, width = catalogue["height"], catalogue["width"]
    channels: dict[str, Any] = {}
    for layer in catalogue["layers"]:
        raw = client.layer(job_id, layer["name"])
        values = np.frombuffer(raw, dtype="<f4").reshape(height, width, layer["channels"])
        if layer["name"] == "rgb":
            channels.update({name: values[..., i] for i, name in enumerate("RGB")})
        else:
            channels[layer["name"]] = values[..., 0]
    return channels
