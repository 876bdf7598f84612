"""``hgrender render --tev`` and ``hgrender view JOB --tev`` against a TCP listener that decodes tev's
packets: the channel names tev is given, the pixel values it receives (equal to image.exr, read back
with OpenImageIO), one update per finished chunk, and the one-line error when no tev listens."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from tests.support.live_service import LiveService
from tests.support.scenes import example, tiny_scene
from tests.support.tev_listener import TevListener

HGRENDER = Path(sys.executable).parent / "hgrender"


def run(*args: str, timeout_s: float = 600) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("HGRENDER_")}
    return subprocess.run([str(HGRENDER), *args], capture_output=True, text=True, timeout=timeout_s, env=env)


@pytest.fixture
def tev() -> Iterator[TevListener]:
    listener = TevListener()
    try:
        yield listener
    finally:
        listener.close()


def closed_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]  # nothing listens once the probe is closed


def small_scene(tmp_path: Path, size_px: int = 12) -> Path:
    """The Cornell box at ``size_px`` square and 4 bands, written to a file for the command line."""
    scene = example("cornell_box", width=size_px, height=size_px, bands=4)
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene))
    return path


def wait_for_updates(tev: TevListener, name: str, channel: str, count: int, timeout_s: float = 10) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with tev.lock:
            if name in tev.images and tev.images[name].updates.get(channel, 0) >= count:
                return
        time.sleep(0.05)
    pytest.fail(f"tev received fewer than {count} updates of {channel} in {name}")


def test_render_streams_every_channel_per_chunk_into_tev(tmp_path: Path, tev: TevListener) -> None:
    scene = small_scene(tmp_path)
    out = tmp_path / "out"
    result = run("render", str(scene), "-o", str(out), "--spp", "4", "--chunks", "2", "--tev", f":{tev.port}")
    assert result.returncode == 0, result.stderr
    exr = read_exr(out / "image.exr")
    name = "hgrender scene"
    wait_for_updates(tev, name, "R", 2)
    image = tev.images[name]
    # The image tev was given has image.exr's channels: R,G,B, then the S0 bands, then the rest.
    assert image.channel_names[:3] == ["R", "G", "B"]
    assert image.channel_names[3:7] == exr.band_names()
    assert set(image.channel_names) == set(exr.channels)
    diagnostics = ("l1_um", "l2_um", "angle", "anisotropy", "area_um2", "r_m", "Mxx", "Mxy", "Myy")
    assert {f"coherence.{k}" for k in diagnostics} <= set(image.channel_names)
    assert (image.width, image.height) == (12, 12)
    # One update per chunk; the last equals the written image (float32 sums vs in-memory float64).
    for channel, values in exr.channels.items():
        assert image.updates[channel] == 2, channel
        np.testing.assert_allclose(image.pixels[channel], values, rtol=1e-4, atol=1e-6, err_msg=channel)
    first, last = image.snapshots["S0." + exr.band_names()[0][3:]]
    assert not np.allclose(first, last)  # the first update held only the first chunk's samples


def test_render_with_no_tev_listening_is_one_line_and_renders_nothing(tmp_path: Path) -> None:
    port = closed_port()
    out = tmp_path / "out"
    result = run("render", str(small_scene(tmp_path)), "-o", str(out), "--tev", f"127.0.0.1:{port}")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"hgrender render: error: tev: no tev listening at 127.0.0.1:{port} (connection refused); start tev "
        "first (it listens on 127.0.0.1:14158 by default) or pass --tev HOST:PORT"
    ]
    assert not out.exists()


def test_tev_address_is_validated(tmp_path: Path) -> None:
    result = run("render", str(small_scene(tmp_path)), "-o", str(tmp_path / "out"), "--tev", "host:99999")
    assert result.returncode == 2
    assert "argument --tev: must be HOST:PORT with a port in 1..65535, got 'host:99999'" in result.stderr


@pytest.mark.slow
def test_view_streams_a_running_job_then_its_final_image(
    live_service: LiveService, tmp_path: Path, tev: TevListener
) -> None:
    # A long job ahead in the one worker's queue keeps ours queued until `view` follows it; canceling the
    # blocker then lets our four chunks run one by one while `view` watches.
    live_service.ensure_worker()
    blocker = live_service.admin.submit(tiny_scene(size_px=64, spp=65536), chunks=1, name="tev view blocker")
    job = live_service.admin.submit(tiny_scene(size_px=24, spp=256), chunks=4, name="tev view")
    common = ["--url", live_service.base_url, "--token", live_service.token]
    env = {k: v for k, v in os.environ.items() if not k.startswith("HGRENDER_")}
    command = [str(HGRENDER), "view", job["id"], "--tev", f"127.0.0.1:{tev.port}", *common]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert process.stderr is not None
        first = process.stderr.readline()  # the first progress line: view follows the queued job
        assert first == f"job {job['id']}:   0% (queued, 0/4 chunks)\n", first
        live_service.admin.cancel(blocker["id"])
        rest = process.stderr.read()
        assert process.wait(timeout=300) == 0, rest
    finally:
        if process.poll() is None:
            process.kill()
    lines = (first + rest).splitlines()
    assert lines[-1] == f"{job['id']}: sent to tev at 127.0.0.1:{tev.port}"
    exr = read_exr(live_service.admin.download(job["id"], "image.exr", tmp_path / "image.exr"))
    name = f"hgrender {job['id']}"
    image = tev.images[name]
    assert image.channel_names[:3] == ["R", "G", "B"]
    assert set(image.channel_names) == set(exr.channels)
    for channel, values in exr.channels.items():
        np.testing.assert_allclose(image.pixels[channel], values, rtol=1e-6, atol=0, err_msg=channel)
    # Followed while running: partial images (chunks finished so far) came before the final one.
    assert image.updates["R"] >= 2, lines
    assert not np.allclose(image.snapshots["R"][0], image.snapshots["R"][-1])
    # Without --tev: the browser viewer's address for the job.
    printed = run("view", job["id"], *common)
    assert printed.stdout.strip() == f"{live_service.base_url}/#/view/{job['id']}"


def test_view_with_no_tev_listening_is_one_line() -> None:
    port = closed_port()
    result = run("view", "0123456789abcdef0123456789abcdef", "--tev", f"127.0.0.1:{port}")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"hgrender view: error: tev: no tev listening at 127.0.0.1:{port} (connection refused); start tev "
        "first (it listens on 127.0.0.1:14158 by default) or pass --tev HOST:PORT"
    ]
