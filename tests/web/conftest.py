"""Fixtures of the viewer tests: a live ``hgrender serve`` subprocess (auth on, private Redis, one worker,
temporary data dir, free port), tiny rendered jobs of a plane under a cylinder light, their EXRs read
with OpenImageIO, and headless Chromium (Debian's ``/usr/bin/chromium``) driven by Playwright."""

from __future__ import annotations

import contextlib
import copy
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest

from hgcore.artifacts.exr import ExrImage, read_exr
from hgrender.client import HgrenderClient
from schemas import build
from service.redis_server import free_loopback_port

REPO_ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS_DIR = REPO_ROOT / "test-artifacts"
SIZE_PX = 24
SPP = 4

# A diffuse plane (y = 0) seen straight from above (camera up = world −z, so image +x = world +x and
# image +y up = world −z) under a thin cylinder light with unit axis a. Seen from a floor point along the
# unit direction d to the cylinder, the source is a strip along the projection of a onto the transverse
# plane, so coherence is longest across it: ℓ₁ ∥ d × a. For a = x̂: d × a = (0, d_z, −d_y), whose
# image-plane (x, −z) components are (0, d_y): vertical (angle ±π/2) at every floor pixel. For
# a = (x̂ + ẑ)/√2: d × a ∝ (d_y, d_z − d_x, −d_y) → image (d_y, d_y): angle π/4 everywhere.
CYLINDER_SCENE: dict[str, Any] = build.scene(
    "plane under a cylinder light",
    camera=build.camera([0, 1.0, 0], [0, 0, 0], up=[0, 0, -1], fov_deg=40),
    film={"width": SIZE_PX, "height": SIZE_PX, "bands": 8, "spp": SPP},
    materials={"floor": {"type": "diffuse", "reflectance": 0.5}},
    shapes=[build.rectangle([0, 0, 0], normal=[0, 1, 0], up=[0, 0, -1], width_m=2, material="floor")],
    emitters=[
        {
            "type": "cylinder",
            "p0_m": [-0.3, 0.5, 0],
            "p1_m": [0.3, 0.5, 0],
            "radius_m": 0.002,
            "spectrum": {"type": "cie_f", "name": "F11"},
            "power_w": 10,
        }
    ],
)


def cylinder_scene(axis_end_m: tuple[float, float] = (0.3, 0.0), **film: Any) -> dict[str, Any]:
    """The scene with film overrides; the cylinder runs from −end to +end in (x, z) at height 0.5 m."""
    scene = copy.deepcopy(CYLINDER_SCENE)
    scene["film"].update(film)
    end_x_m, end_z_m = axis_end_m
    scene["emitters"][0]["p0_m"] = [-end_x_m, 0.5, -end_z_m]
    scene["emitters"][0]["p1_m"] = [end_x_m, 0.5, end_z_m]
    return scene


@dataclass
class Served:
    """A running ``hgrender serve`` and an admin client for it."""

    base_url: str
    token: str
    data_dir: Path
    client: HgrenderClient

    def get(self, path: str, token: str | None = None, **params: Any) -> httpx.Response:
        headers = {"Authorization": f"Bearer {token if token is not None else self.token}"}
        return httpx.get(self.base_url + path, headers=headers, params=params, timeout=60)

    def wait_final(self, job_id: str, timeout_s: float = 120.0) -> dict[str, Any]:
        """Poll the job until a final status (fails the test after ``timeout_s``, so that a job stuck
        in a broken worker cannot hang the suite)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            view = self.client.get(job_id)
            if view["status"] in ("succeeded", "failed", "canceled"):
                return view
            time.sleep(0.2)
        pytest.fail(f"job {job_id} not finished after {timeout_s} s: {self.client.get(job_id)}")

    def render(self, scene: dict[str, Any], name: str, **options: Any) -> str:
        """Submit and wait for success; returns the job id."""
        job = self.client.submit(scene, name=name, **options)
        final = self.wait_final(job["id"])
        assert final["status"] == "succeeded", final
        return job["id"]


@pytest.fixture(scope="session")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    """``hgrender serve`` as users run it (a private Redis because REDIS_URL is unset), auth on."""
    data_dir = tmp_path_factory.mktemp("viewer-data")
    port = free_loopback_port()
    env = {k: v for k, v in os.environ.items() if k not in ("REDIS_URL", "HGRENDER_REDIS_URL")}
    env |= {"HGRENDER_AUTH": "on", "HGRENDER_PROGRESS_INTERVAL_S": "0.1", "HGRENDER_DEFAULT_CHUNKS": "2"}
    # The console script's interpreter with the repository on sys.path (as worker_command_line does).
    command = [sys.executable, "-c", "import sys; from hgrender.cli import main; sys.exit(main())"]
    command += [
        "serve",
        "--host",
        "127.0.0.1",
        "--port",
        str(port),
        "--data-dir",
        str(data_dir),
        "--workers",
        "1",
    ]
    log = (data_dir / "serve.log").open("wb")
    process = subprocess.Popen(
        command, cwd=REPO_ROOT, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
    )
    base_url = f"http://127.0.0.1:{port}"
    token_file = data_dir / "admin.token"
    deadline = time.monotonic() + 60
    while True:
        if process.poll() is not None:
            raise RuntimeError(f"hgrender serve exited: {(data_dir / 'serve.log').read_text()[-2000:]}")
        with contextlib.suppress(httpx.HTTPError):
            if token_file.exists() and httpx.get(base_url + "/healthz", timeout=2).status_code == 200:
                break
        if time.monotonic() > deadline:
            raise RuntimeError("hgrender serve did not become healthy within 60 s")
        time.sleep(0.2)
    token = token_file.read_text().strip()
    client = HgrenderClient(base_url, token=token)
    try:
        yield Served(base_url, token, data_dir, client)
    finally:
        client.close()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
        log.close()


@dataclass
class RenderedJob:
    job_id: str
    exr: ExrImage


@pytest.fixture(scope="session")
def cylinder_job(served: Served, tmp_path_factory: pytest.TempPathFactory) -> RenderedJob:
    job_id = served.render(cylinder_scene(), "cylinder")
    out_dir = tmp_path_factory.mktemp("cylinder-job")
    served.client.download(job_id, "image.exr", out_dir / "image.exr")
    return RenderedJob(job_id, read_exr(out_dir / "image.exr"))


@pytest.fixture(scope="session")
def cylinder_job_reseeded(served: Served, tmp_path_factory: pytest.TempPathFactory) -> RenderedJob:
    """The same scene with another seed: a different noise pattern to compare against."""
    job_id = served.render(cylinder_scene(seed=7), "cylinder seed 7")
    out_dir = tmp_path_factory.mktemp("cylinder-job-7")
    served.client.download(job_id, "image.exr", out_dir / "image.exr")
    return RenderedJob(job_id, read_exr(out_dir / "image.exr"))


@pytest.fixture(scope="session")
def diagonal_cylinder_job(served: Served, tmp_path_factory: pytest.TempPathFactory) -> RenderedJob:
    """The cylinder along (x̂ + ẑ)/√2: ℓ₁ at +45° in the image (up and to the right)."""
    job_id = served.render(cylinder_scene(axis_end_m=(0.3, 0.3)), "diagonal cylinder")
    out_dir = tmp_path_factory.mktemp("diagonal-job")
    served.client.download(job_id, "image.exr", out_dir / "image.exr")
    return RenderedJob(job_id, read_exr(out_dir / "image.exr"))


@contextlib.contextmanager
def token_page(chromium: Any, token: str, width: int, height: int, **context_options: Any) -> Iterator[Any]:
    """A ``width``×``height`` page with ``token`` in localStorage; fails the test on page errors."""
    context = chromium.new_context(viewport={"width": width, "height": height}, **context_options)
    context.add_init_script(f"window.localStorage.setItem('hgrender.token', {token!r});")
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    try:
        yield page
    finally:
        context.close()
    assert not errors, f"page errors: {errors}"


@pytest.fixture
def page(chromium: Any, served: Served) -> Iterator[Any]:
    """A 1280×800 page with the admin token in localStorage; fails the test on page errors."""
    with token_page(chromium, served.token, 1280, 800) as page:
        yield page


def screenshot(page: Any, name: str) -> Path:
    ARTIFACTS_DIR.mkdir(exist_ok=True)
    path = ARTIFACTS_DIR / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    return path
