"""Bad input versus bugs (issue 15): ``hgcore.errors.InputError`` is a client error (HTTP 422, CLI exit 2),
every other exception a programming error (HTTP 500 with the traceback in the server log, CLI traceback
and exit 1)."""

from __future__ import annotations

import argparse
import logging
import subprocess
import sys
import threading
import time

import httpx
import pytest
import uvicorn
from fastapi import FastAPI

import hgrender.cli
from hgcore.errors import InputError
from schemas import SceneError
from service.api.errors import install_exception_handlers
from service.redis_server import free_loopback_port


def api_with_failing_routes() -> FastAPI:
    app = FastAPI()
    install_exception_handlers(app)

    @app.get("/input")
    def bad_input() -> None:
        raise InputError("x: must be in [0, 15], got 16")

    @app.get("/bug")
    def bug() -> None:
        raise ValueError("math domain error")  # what a programming bug raises

    @app.get("/scene")
    def bad_scene() -> None:
        raise SceneError.at("/film/spp", "Input should be greater than 0")

    return app


def test_input_errors_are_422_and_bugs_are_500_with_the_traceback_logged(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Over real HTTP (uvicorn on a free loopback port), as the API runs in ``hgrender serve``."""
    port = free_loopback_port()
    server = uvicorn.Server(
        uvicorn.Config(api_with_failing_routes(), host="127.0.0.1", port=port, log_config=None)
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        base = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 30
        while not server.started and time.monotonic() < deadline:
            time.sleep(0.05)
        response = httpx.get(base + "/input")
        assert response.status_code == 422
        assert response.json() == {"detail": "x: must be in [0, 15], got 16"}
        assert httpx.get(base + "/scene").status_code == 422
        caplog.set_level(logging.ERROR)
        response = httpx.get(base + "/bug")
        assert response.status_code == 500
        assert "math domain error" not in response.text  # a bug's message is not the client's business
        deadline = time.monotonic() + 10  # uvicorn logs from its own thread, after the response
        while "math domain error" not in caplog.text and time.monotonic() < deadline:
            time.sleep(0.05)
        assert "Exception in ASGI application" in caplog.text and "math domain error" in caplog.text
    finally:
        server.should_exit = True
        thread.join(timeout=10)


def _run_cli_with(handler_error: Exception, monkeypatch: pytest.MonkeyPatch) -> int:
    def build_parser() -> argparse.ArgumentParser:
        parser = argparse.ArgumentParser(prog="hgrender")
        parser.set_defaults(command="probe", handler=lambda _: (_ for _ in ()).throw(handler_error))
        return parser

    monkeypatch.setattr(hgrender.cli, "build_parser", build_parser)
    return hgrender.cli.main([])


def test_cli_exits_2_on_input_errors_and_lets_bugs_raise(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _run_cli_with(InputError("spp: must be at least 1, got 0"), monkeypatch) == 2
    assert capsys.readouterr().err == "hgrender probe: error: spp: must be at least 1, got 0\n"
    with pytest.raises(ValueError, match="math domain error"):
        _run_cli_with(ValueError("math domain error"), monkeypatch)


def test_a_bad_flag_of_a_real_command_is_one_line_and_exit_2() -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from hgrender.cli import main; sys.exit(main())",
            "coherence",
            "--source",
            "sphere",
            "--radius",
            "-1",
            "--distance",
            "0.6",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr and "radius" in result.stderr
