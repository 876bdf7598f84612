"""The client commands as a new user meets them (the console script in a subprocess, HGRENDER_* unset):
a service that is down, a wrong port or path, a bad or missing token, and a rejected scene each give
the exact message below and exit 2, never a traceback; a good submission shows its progress."""

from __future__ import annotations

import http.server
import json
import os
import socket
import subprocess
import sys
import threading
from pathlib import Path

import httpx
import pytest

from tests.support.live_service import LiveService
from tests.support.scenes import tiny_scene

pytestmark = pytest.mark.slow

HGRENDER = Path(sys.executable).parent / "hgrender"
JOB_ID = "0123456789abcdef0123456789abcdef"


def run(*args: str, timeout_s: float = 300, **env: str) -> subprocess.CompletedProcess[str]:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("HGRENDER_")}
    return subprocess.run(
        [str(HGRENDER), *args], capture_output=True, text=True, timeout=timeout_s, env=clean | env
    )


def closed_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def error_lines(result: subprocess.CompletedProcess[str]) -> list[str]:
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    assert "Traceback" not in result.stderr
    return result.stderr.strip().splitlines()


def unreachable(command: str, url: str, reason: str, source: str) -> str:
    return (
        f"hgrender {command}: error: url: cannot reach the hgrender service at {url} ({reason}; URL from "
        f"{source}); start it with `hgrender serve` or set its address with --url or HGRENDER_URL"
    )


CLIENT_COMMANDS: dict[str, list[str]] = {
    "submit": ["submit", "SCENE"],
    "status": ["status", JOB_ID],
    "list": ["list"],
    "download": ["download", JOB_ID],
    "cancel": ["cancel", JOB_ID],
    "regress": ["regress", "SUITE", "--url"],
}


@pytest.mark.parametrize("command", sorted(CLIENT_COMMANDS))
def test_service_down_is_one_line_naming_the_url(command: str, tmp_path: Path) -> None:
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(tiny_scene()))
    suite = tmp_path / "suite.json"
    suite.write_text(json.dumps({"scenes": [{"example": "cornell_box", "spp": 2}]}))
    port = closed_port()
    url = f"http://127.0.0.1:{port}"
    args = [{"SCENE": str(scene), "SUITE": str(suite)}.get(a, a) for a in CLIENT_COMMANDS[command]]
    if command == "regress":
        result = run(*args, url, "--data-dir", str(tmp_path))
        assert error_lines(result) == [unreachable(command, url, "connection refused", "--url")]
        return
    result = run(*args, "--data-dir", str(tmp_path), HGRENDER_URL=url)
    assert error_lines(result) == [unreachable(command, url, "connection refused", "HGRENDER_URL")]


def test_default_url_and_an_unknown_host_are_named(tmp_path: Path) -> None:
    result = run("list", "--url", "http://no-such-host.invalid:8000")
    assert error_lines(result) == [
        unreachable("list", "http://no-such-host.invalid:8000", "name or service not known", "--url")
    ]
    result = run("status", JOB_ID, "--url", "127.0.0.1:8000")
    assert error_lines(result) == [
        "hgrender status: error: url: '127.0.0.1:8000' (from --url) is not an http:// or https:// URL; "
        "e.g. http://127.0.0.1:8000"
    ]


def test_wrong_path_says_no_hgrender_api_there(live_service: LiveService) -> None:
    url = live_service.base_url + "/api"
    result = run("list", "--url", url, "--token", live_service.token)
    assert error_lines(result) == [
        f"hgrender list: error: url: no hgrender API at {url} (URL from --url): HTTP 404 for GET "
        "/api/v1/jobs; set the service's base URL, e.g. http://127.0.0.1:8000, with --url or HGRENDER_URL"
    ]


def test_bad_and_missing_tokens_say_where_the_cli_looked(live_service: LiveService, tmp_path: Path) -> None:
    hint = (
        "pass a valid token with --token or HGRENDER_TOKEN, or --data-dir DIR of the `hgrender serve` that "
        "wrote DIR/admin.token (`hgrender token create` makes more)"
    )
    result = run(
        "list", "--data-dir", str(tmp_path), HGRENDER_URL=live_service.base_url, HGRENDER_TOKEN="nope"
    )
    assert error_lines(result) == [
        "hgrender list: error: authorization: malformed bearer token (HTTP 401; token from HGRENDER_TOKEN); "
        + hint
    ]
    wrong = "hgr_" + "0" * 40
    result = run(
        "status", JOB_ID, "--url", live_service.base_url, "--token", wrong, "--data-dir", str(tmp_path)
    )
    assert error_lines(result)[0].startswith("hgrender status: error: authorization: ")
    assert error_lines(result)[0].endswith(f"(HTTP 401; token from --token); {hint}")
    result = run("list", "--url", live_service.base_url, "--data-dir", str(tmp_path))
    assert error_lines(result) == [
        "hgrender list: error: authorization: missing bearer token (HTTP 401; token from nowhere: no "
        f"--token, HGRENDER_TOKEN unset, no {tmp_path}/admin.token); {hint}"
    ]
    # The serve's own data dir: its admin.token is found and used.
    result = run("list", "--url", live_service.base_url, "--data-dir", str(live_service.data_dir))
    assert result.returncode == 0, result.stderr


def test_submit_lists_every_validation_problem(live_service: LiveService, tmp_path: Path) -> None:
    scene = tiny_scene()
    scene["film"].update(bands=0, width=-4)
    scene["camera"]["fov_deg"] = "wide"
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(scene))
    api = httpx.post(
        live_service.base_url + "/v1/jobs",
        json={"scene": scene},
        headers={"Authorization": f"Bearer {live_service.token}"},
        timeout=30,
    )
    assert api.status_code == 422
    problems = api.json()["errors"]
    assert len(problems) >= 3
    result = run("submit", str(path), "--url", live_service.base_url, "--token", live_service.token)
    assert error_lines(result) == [
        f"hgrender submit: error: HTTP 422: {len(problems)} problems in {path}:",
        *(f"  {p['pointer'] or '/'}: {p['message']}" for p in problems),
    ]
    assert {"/film/bands", "/film/width", "/camera/fov_deg"} <= {p["pointer"] for p in problems}


def test_submit_json_syntax_error_names_file_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "broken.json"
    path.write_text('{\n  "schema": "hgrender/scene/v1",\n  "film" {}\n}\n')
    assert error_lines(run("submit", str(path))) == [
        f"hgrender submit: error: scene: {path}:3:10: not valid JSON: Expecting ':' delimiter"
    ]


def test_submit_options_are_validated(tmp_path: Path) -> None:
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(tiny_scene()))
    for option, value in (("--width", "0"), ("--height", "-3"), ("--bands", "x"), ("--spp", "0")):
        lines = error_lines(run("submit", str(path), option, value))
        assert (
            lines[-1]
            == f"hgrender submit: error: argument {option}: must be a positive integer, got {value!r}"
        )
    lines = error_lines(run("submit", str(path), "--seed", "-1"))
    assert (
        lines[-1]
        == "hgrender submit: error: argument --seed: must be an integer in [0, 4294967295], got '-1'"
    )
    usd = tmp_path / "scene.usda"
    usd.write_text("#usda 1.0\n")
    assert error_lines(run("submit", str(usd), "--width", "8", "--bands", "4")) == [
        "hgrender submit: error: width: --width, --bands apply to .json scenes only "
        "(a USD stage sets its own film)"
    ]


def test_submit_wait_with_film_overrides_writes_one_progress_line_per_step(
    live_service: LiveService, tmp_path: Path
) -> None:
    live_service.ensure_worker()
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(tiny_scene(size_px=16)))
    result = run(
        "submit", str(path), "--wait", "--width", "10", "--height", "6", "--bands", "3", "--spp", "2",
        "--chunks", "2", "--name", "cli override",
        HGRENDER_URL=live_service.base_url, HGRENDER_TOKEN=live_service.token,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    job_id = result.stdout.splitlines()[0]
    assert json.loads(result.stdout.splitlines()[-1]) == {"id": job_id, "status": "succeeded", "error": None}
    lines = result.stderr.splitlines()
    assert "\r" not in result.stderr  # no redraws without a terminal
    assert lines[-1] == f"job {job_id}: 100% (succeeded, 2/2 chunks)"
    assert all(line.startswith(f"job {job_id}: ") for line in lines)
    assert len(lines) == len(set(lines))  # one line per step, no repeats
    assert any("running" in line for line in lines)
    summary = live_service.admin.download(job_id, "summary.json", tmp_path / "summary.json")
    summary = json.loads(summary.read_text())
    assert (summary["width"], summary["height"], summary["bands"], summary["spp"]) == (10, 6, 3, 2)
    listed = run("list", "--url", live_service.base_url, "--token", live_service.token)
    assert any(
        line.startswith(job_id) and line.endswith("cli override") for line in listed.stdout.splitlines()
    )


class _HtmlEverywhere(http.server.BaseHTTPRequestHandler):
    """Some other web server: 200 and an HTML page for every path."""

    def do_GET(self) -> None:
        body = b"<html><body>not hgrender</body></html>"
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args: object) -> None:
        pass


def test_another_web_server_is_not_taken_for_the_api(tmp_path: Path) -> None:
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _HtmlEverywhere)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_address[1]}"
    try:
        result = run("status", JOB_ID, "--url", url, "--data-dir", str(tmp_path))
    finally:
        server.shutdown()
    assert error_lines(result) == [
        f"hgrender status: error: url: no hgrender API at {url} (URL from --url): HTTP 200 with a non-JSON "
        f"answer for GET /v1/jobs/{JOB_ID}; set the service's base URL, e.g. http://127.0.0.1:8000, with "
        "--url or HGRENDER_URL"
    ]


def test_submit_passes_the_integrator_and_noise_target_options(
    live_service: LiveService, tmp_path: Path
) -> None:
    live_service.ensure_worker()
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(tiny_scene(size_px=8, spp=2)))
    result = run(
        "submit", str(path), "--wait", "--integrator", "rlt", "--target-rel-error", "0.2",
        "--time-budget-s", "60", HGRENDER_URL=live_service.base_url, HGRENDER_TOKEN=live_service.token,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    job_id = result.stdout.splitlines()[0]
    view = live_service.admin.get(job_id)
    assert view["noise_target"]["target_rel_error"] == 0.2
    assert view["noise_target"]["time_budget_s"] == 60
    summary = json.loads(live_service.admin.download(job_id, "summary.json", tmp_path / "s.json").read_text())
    assert summary["integrator"] == "rlt"
    assert summary["noise_target"]["met"] is True
    assert summary["noise_target"]["achieved_rel_error"] <= 0.2
