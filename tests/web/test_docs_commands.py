"""Every shell block of README.md and docs/api.md runs as written (issue 29): what a newcomer copies into a
terminal must work on a fresh clone, fail loudly where it fails, and leave the service's log readable.

Each document's blocks run in order as one bash script (``set -euo pipefail``; variables such as ``$JOB``
carry from block to block, as in one terminal) in a scratch directory that holds the repository's files
(symlinks) and ``data`` → the data dir of the module's ``live_service`` (``tests/support/live_service.py``:
auth on, one worker), so ``cat data/admin.token`` reads its token. Two things are adapted, both as a user
would: the service's address ``127.0.0.1:8000`` becomes the live service's (8000 may be taken on a shared
machine), and ``HGRENDER_URL`` names it for the client commands (README: "find the
service in --url / HGRENDER_URL"). ``make serve`` runs as written too, on a free ``PORT`` and a scratch
``DATA_DIR`` from the environment (as the README says), and is stopped with Ctrl-C through a terminal.
What is not run here, and why, is listed in ``NOT_RUN_HERE``; a listed command that the documents no
longer contain fails the test, so the list cannot go stale. The renders the documents ask for are small
(64² and 128² Cornell boxes, 16–64 spp, a 32² regression scene): about 30 s in all on two cores.
"""

from __future__ import annotations

import contextlib
import os
import pty
import re
import select
import shutil
import signal
import subprocess
import time
from pathlib import Path

import httpx
import pytest

from service.redis_server import free_loopback_port
from tests.support import REPO_ROOT
from tests.support.live_service import LiveService

DOCUMENTS = ("README.md", "docs/api.md")
SHELL_BLOCK = re.compile(r"^```(?:sh|bash|shell)\n(.*?)^```", re.MULTILINE | re.DOTALL)
DOCUMENTED_ADDRESS = "127.0.0.1:8000"
NOT_RUN_HERE = {
    "make test": "the whole suite, of which this test is part",
    "make bench": "benchmarks run for minutes; bench/ is not part of the suite",
    ".venv/bin/python -m bench": "as make bench",
    ".venv/bin/python -m bench.bench_api": "as make bench",
}
LONG_RUNNING = "make serve"  # run separately: started, seen healthy, stopped with Ctrl-C
STARTS_SERVICE = re.compile(r"\b(hgrender|make) serve\b")  # never ends: never run inside a script
SCRIPT_TIMEOUT_S = 300

pytestmark = pytest.mark.slow  # end to end: seven CLI processes, two local renders, a second service


def command_of(line: str) -> str:
    """A line without its trailing ``# comment`` (the documents put two spaces before one)."""
    return re.split(r"\s{2,}#", line, maxsplit=1)[0].strip()


def shell_blocks(document: str) -> list[str]:
    return SHELL_BLOCK.findall((REPO_ROOT / document).read_text())


def runnable_script(document: str, base_url: str) -> tuple[str, list[str]]:
    """The document's blocks as one script for this session's service, and the commands left out."""
    lines, left_out = ["set -euo pipefail"], []
    for block in shell_blocks(document):
        for line in block.splitlines():
            command = command_of(line)
            if command in NOT_RUN_HERE or STARTS_SERVICE.search(command):
                left_out.append(command)
                lines.append(f": not run here: {command}")
            else:
                lines.append(line.replace(DOCUMENTED_ADDRESS, base_url.removeprefix("http://")))
    return "\n".join(lines) + "\n", left_out


@pytest.fixture(scope="module")
def fresh_clone(tmp_path_factory: pytest.TempPathFactory, live_service: LiveService) -> Path:
    """A scratch directory with the repository's top-level entries (symlinks) and ``data`` → the session
    service's data dir; commands write their outputs (out/, image.exr, baselines/ …) here."""
    directory = tmp_path_factory.mktemp("fresh-clone")
    for entry in REPO_ROOT.iterdir():
        if entry.name not in {"data", "out", "test-artifacts", ".git"}:
            (directory / entry.name).symlink_to(entry)
    (directory / "data").symlink_to(live_service.data_dir)
    return directory


def run_script(script: str, cwd: Path, live_service: LiveService) -> subprocess.CompletedProcess[str]:
    """Run ``script`` with bash in its own process group; past SCRIPT_TIMEOUT_S the whole group is stopped
    (SIGTERM: a service a block started shuts down its workers and Redis too), and the test fails."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("HGRENDER_") and k != "REDIS_URL"}
    env["HGRENDER_URL"] = live_service.base_url
    process = subprocess.Popen(
        ["bash", "-c", script],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        stdout, stderr = process.communicate(timeout=SCRIPT_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            stdout, stderr = process.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            stdout, stderr = process.communicate()
        pytest.fail(f"the blocks ran longer than {SCRIPT_TIMEOUT_S} s: {stdout[-2000:]}{stderr[-2000:]}")
    return subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)


def tracked_files() -> set[str] | None:
    if shutil.which("git") is None or not (REPO_ROOT / ".git").exists():
        return None
    listing = subprocess.run(["git", "ls-files"], cwd=REPO_ROOT, capture_output=True, text=True, check=True)
    return set(listing.stdout.splitlines())


def test_the_documents_left_out_list_is_current() -> None:
    """Every command the test does not run is still in a document (the list cannot go stale), and every
    repository file a block names is tracked by git (it exists on a fresh clone, not just here)."""
    commands = {
        command_of(line) for doc in DOCUMENTS for block in shell_blocks(doc) for line in block.splitlines()
    }
    assert set(NOT_RUN_HERE) | {LONG_RUNNING} <= commands
    # A command that starts a service would never end: the only one a block may hold is LONG_RUNNING.
    servers = {c for c in commands if STARTS_SERVICE.search(c) and c != LONG_RUNNING}
    assert not servers, f"blocks start a service; run it apart as {LONG_RUNNING!r} is: {servers}"
    tracked = tracked_files()
    if tracked is None:
        pytest.skip("not a git checkout: cannot tell tracked files")
    named = {
        word.split("@", 1)[-1].rstrip("/")
        for doc in DOCUMENTS
        for block in shell_blocks(doc)
        for word in re.findall(r"[\w@.-]+/[\w./-]+", block)
    }
    # .venv/ is made by `make setup`, not cloned.
    in_repository = {path for path in named if (REPO_ROOT / path).is_file() and not path.startswith(".venv/")}
    assert in_repository >= {"schemas/examples/cornell_box.json", "docs/examples/cornell_box.usda"}
    assert in_repository <= tracked, in_repository - tracked


def test_readme_blocks_run_as_written(live_service: LiveService, fresh_clone: Path) -> None:
    script, left_out = runnable_script("README.md", live_service.base_url)
    assert set(left_out) == set(NOT_RUN_HERE) | {LONG_RUNNING}
    result = run_script(script, fresh_clone, live_service)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    # What the commands were for is there: the local render, the regression report, the service job's
    # artifacts, the curl download.
    for produced in ("out/image.exr", "report.xml", "out-job/image.exr", "image.exr"):
        assert (fresh_clone / produced).stat().st_size > 0, produced
    assert 'failures="0"' in (fresh_clone / "report.xml").read_text()
    # `submit --wait` (no terminal: one line per step) never claims 100 % while the job still runs.
    assert not re.search(r"100% \((running|merging)", result.stderr), result.stderr


def test_api_blocks_run_as_written(live_service: LiveService, fresh_clone: Path) -> None:
    script, left_out = runnable_script("docs/api.md", live_service.base_url)
    assert left_out == []
    result = run_script(script, fresh_clone, live_service)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert (fresh_clone / "image.exr").stat().st_size > 0
    assert (fresh_clone / "preview.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The multipart line rendered the USD file the repository ships.
    usd_jobs = [
        job for job in live_service.admin.list(limit=100)["items"] if job["name"] == "Cornell box from USD"
    ]
    assert usd_jobs and live_service.wait_final(usd_jobs[0]["id"])["status"] == "succeeded"


def test_make_serve_starts_and_a_ctrl_c_stops_it_quietly(tmp_path: Path) -> None:
    """`make serve` as the README says (PORT, DATA_DIR from the environment) in a terminal; Ctrl-C (the
    terminal's SIGINT to the foreground group: make and serve) ends it in order, without make's
    "*** [Makefile:…: serve] Error 130" or a traceback; and its log at INFO has no periodic noise."""
    up_to_date = subprocess.run(["make", "-q", ".venv/.installed"], cwd=REPO_ROOT, capture_output=True)
    if up_to_date.returncode != 0:
        pytest.skip("the virtual environment is older than pyproject.toml: make serve would reinstall it")
    port = free_loopback_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("HGRENDER_") and k != "REDIS_URL"}
    # RQ's registry maintenance every second (5 s by default), so that a few passes fall in the run.
    env |= {
        "PORT": str(port),
        "DATA_DIR": str(tmp_path / "data"),
        "HGRENDER_WORKER_MAINTENANCE_INTERVAL_S": "1",
    }
    pid, terminal = pty.fork()
    if pid == 0:  # the child: make in the terminal's foreground group
        os.chdir(REPO_ROOT)
        os.execvpe("make", ["make", *LONG_RUNNING.split()[1:]], env)
    output = b""

    def read_for(seconds: float) -> None:
        nonlocal output
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            ready, _, _ = select.select([terminal], [], [], 0.1)
            if ready:
                with contextlib.suppress(OSError):
                    output += os.read(terminal, 65536)

    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            read_for(0.3)
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=2).status_code == 200:
                    break
        else:
            pytest.fail(f"make serve did not become healthy: {output.decode(errors='replace')[-2000:]}")
        assert (tmp_path / "data" / "admin.token").exists()  # DATA_DIR was used
        read_for(4.0)  # several maintenance passes, which must not reach the log at INFO
        os.write(terminal, b"\x03")  # Ctrl-C, as typed
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            read_for(0.2)
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
        else:
            pytest.fail(f"make serve did not stop after Ctrl-C: {output.decode(errors='replace')[-2000:]}")
    finally:
        with contextlib.suppress(ChildProcessError, ProcessLookupError):
            if os.waitpid(pid, os.WNOHANG)[0] == 0:
                os.killpg(os.getpgid(pid), signal.SIGKILL)
                os.waitpid(pid, 0)
        os.close(terminal)
    text = output.decode(errors="replace")
    assert f"hgrender serve: API      http://127.0.0.1:{port}" in text
    assert "shutting down" in text, text[-2000:]
    assert "make: ***" not in text and "Error 130" not in text, text[-2000:]
    assert "Traceback" not in text, text[-2000:]
    # The serve log at INFO has no periodic noise: RQ's registry maintenance (four lines a pass before,
    # over half of a serve.log) is logged at DEBUG, while the worker's own lines are there.
    assert "rq.worker" in text, text[-2000:]
    assert "cleaning registries" not in text and "cleaning group registries" not in text, text[-2000:]
    # make ends quietly either way the race between its own SIGINT and its recipe goes: killed by the
    # signal it was sent (it saw the interrupt first), or exiting 0 (the recipe's `|| [ $? -eq 130 ]`
    # returned first; seen in a fresh-clone CI run).
    interrupted = os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGINT
    assert interrupted or (os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0), status
