"""A small cluster on this one machine out of network namespaces (issue 8): Redis on one host, the API on
a second, a worker on each of a third and fourth, all linked by veth pairs to a bridge that lives in a
fifth ("switch") namespace, so nothing touches the root namespace's network. Every service listens and
connects on its own 10.77.0.x address only; the artifact store is a shared directory (the filesystem store),
visible to all hosts because network namespaces share the file system.

Checks: a 4-chunk job is split across both worker hosts (each completes chunks; Redis sees both hosts'
addresses) and succeeds; in a second job one worker host is cut off (its link set down) while it renders a
chunk, and the job still succeeds with every chunk and the merge completed exactly once and one set of
artifacts. The test reads Redis through a unix socket of the same server (the test process stays in the
root namespace) and talks HTTP with curl run inside the Redis host's namespace.

Needs root and iproute2 (``ip netns``); skips with the reason otherwise. Bounded by pytest-timeout.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import redis

from hgcore.jobs.lifecycle import JobLifecycle
from hgcore.settings import Settings
from hgcore.store.filesystem import FilesystemStore
from hgrender.cli.service import worker_command_line
from tests.support.processes import wait_for
from tests.support.scenes import tiny_scene

pytestmark = [pytest.mark.slow, pytest.mark.timeout(180)]

SUBNET_PREFIX = "10.77.0."
HOSTS = {"redis": 1, "api": 2, "host1": 3, "host2": 4}
"""Host name -> last octet of its address on the bridge."""
API_PORT = 8000
REDIS_PORT = 6379


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=10)


def namespaces_unavailable() -> str | None:
    """Why this machine cannot build the cluster, or None."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    for tool in ("ip", "redis-server", "curl"):
        if shutil.which(tool) is None:
            return f"{tool} is not installed"
    probe = f"hgprobe{os.getpid()}"
    try:
        _ip("netns", "add", probe)
    except subprocess.CalledProcessError as error:
        return f"ip netns add failed: {error.stderr.decode(errors='replace').strip()}"
    _ip("netns", "del", probe)
    return None


@dataclass
class Cluster:
    """The namespaces, their processes and how to reach the services."""

    tag: str
    work_dir: Path
    processes: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)

    def ns(self, host: str) -> str:
        return f"hg{self.tag}-{host}"

    def address(self, host: str) -> str:
        return SUBNET_PREFIX + str(HOSTS[host])

    @property
    def redis_url(self) -> str:
        return f"redis://{self.address('redis')}:{REDIS_PORT}/0"

    @property
    def api_url(self) -> str:
        return f"http://{self.address('api')}:{API_PORT}"

    @property
    def redis_socket(self) -> Path:
        return self.work_dir / "redis.sock"

    def build_network(self) -> None:
        """A bridge in the switch namespace and one veth pair per host (the host end named eth0)."""
        switch = self.ns("switch")
        _ip("netns", "add", switch)
        _ip("-n", switch, "link", "add", "br0", "type", "bridge")
        _ip("-n", switch, "link", "set", "br0", "up")
        for host, octet in HOSTS.items():
            namespace = self.ns(host)
            _ip("netns", "add", namespace)
            _ip("-n", switch, "link", "add", f"port{octet}", "type", "veth", "peer", "name", f"peer{octet}")
            _ip("-n", switch, "link", "set", f"peer{octet}", "netns", namespace)
            _ip("-n", switch, "link", "set", f"port{octet}", "master", "br0", "up")
            _ip("-n", namespace, "link", "set", f"peer{octet}", "name", "eth0")
            _ip("-n", namespace, "addr", "add", f"{self.address(host)}/24", "dev", "eth0")
            _ip("-n", namespace, "link", "set", "eth0", "up")
            _ip("-n", namespace, "link", "set", "lo", "up")

    def start(self, host: str, name: str, command: list[str], env: dict[str, str] | None = None) -> None:
        """Run ``command`` inside ``host``'s namespace (``ip netns exec`` execs it: same pid), in its own
        session so that teardown can kill it with its children."""
        log = (self.work_dir / f"{name}.log").open("wb")
        self.processes[name] = subprocess.Popen(
            ["ip", "netns", "exec", self.ns(host), *command],
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )

    def service_env(self) -> dict[str, str]:
        """The same settings for API and workers (as one ConfigMap would give them): fast failure
        detection (heartbeat TTL 1 + 3 s, maintenance every 2 s) and immediate retries."""
        settings = Settings(
            redis_url=self.redis_url,
            data_dir=self.work_dir / "data",
            store="filesystem",
            store_dir=self.work_dir / "artifacts",
            workers=0,
            regression_scheduler=False,
            worker_monitoring_interval_s=1,
            worker_heartbeat_grace_s=3,
            worker_maintenance_interval_s=2,
            chunk_retry_intervals_s=[0],
            progress_interval_s=0.1,
        )
        return {**os.environ, **settings.to_env()}

    def curl(self, method: str, path: str, body: dict[str, Any] | None = None) -> dict[str, Any]:
        """An HTTP call to the API from the Redis host (over the bridge), as JSON."""
        token = (self.work_dir / "data" / "admin.token").read_text().strip()
        command = ["ip", "netns", "exec", self.ns("redis"), "curl", "-sS", "--fail-with-body", "-X", method]
        command += ["-H", f"Authorization: Bearer {token}", "--max-time", "20"]
        if body is not None:
            command += ["-H", "Content-Type: application/json", "--data-binary", json.dumps(body)]
        done = subprocess.run([*command, self.api_url + path], capture_output=True, text=True, timeout=30)
        assert done.returncode == 0, (done.stdout, done.stderr)
        return json.loads(done.stdout)

    def stop(self) -> None:
        for process in self.processes.values():
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(process.pid, signal.SIGKILL)
        for process in self.processes.values():
            process.wait(timeout=10)
        for host in [*HOSTS, "switch"]:
            subprocess.run(["ip", "netns", "del", self.ns(host)], capture_output=True, timeout=10)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Cluster]:
    reason = namespaces_unavailable()
    if reason:
        pytest.skip(f"no multi-host cluster: {reason}")
    cluster = Cluster(tag=uuid.uuid4().hex[:6], work_dir=tmp_path_factory.mktemp("cluster"))
    try:
        cluster.build_network()
        (cluster.work_dir / "redis").mkdir()
        cluster.start(
            "redis",
            "redis",
            [
                shutil.which("redis-server") or "redis-server",
                "--bind", cluster.address("redis"),
                "--port", str(REDIS_PORT),
                "--protected-mode", "no",  # reachable from the other hosts' addresses
                "--unixsocket", str(cluster.redis_socket),
                "--dir", str(cluster.work_dir / "redis"),
                "--appendonly", "yes",
            ],
        )  # fmt: skip
        wait_for(cluster.redis_socket.exists, 10, "redis-server")
        env = cluster.service_env()
        # The interpreter-based command line of `hgrender worker`, with `serve` in place of `worker`.
        serve = [*worker_command_line()[:-1], "serve", "--host", cluster.address("api")]
        cluster.start(
            "api", "api", [*serve, "--port", str(API_PORT), "--data-dir", env["HGRENDER_DATA_DIR"]], env
        )
        # host1 starts first and takes RQ's scheduler lock; host2 is the one cut off later.
        cluster.start("host1", "host1", worker_command_line("--name", "host1"), env)
        control = redis.Redis(unix_socket_path=str(cluster.redis_socket))
        wait_for(lambda: control.exists("rq:scheduler-lock:default"), 60, "host1's worker")
        cluster.start("host2", "host2", worker_command_line("--name", "host2"), env)
        wait_for(lambda: control.scard("rq:workers") == 2, 60, "both workers to register")
        wait_for((cluster.work_dir / "data" / "admin.token").exists, 30, "the API's admin token")
        wait_for(lambda: _ready(cluster), 30, "the API to answer /readyz")
        control.close()
        yield cluster
    finally:
        cluster.stop()


def _ready(cluster: Cluster) -> bool:
    with contextlib.suppress(AssertionError, json.JSONDecodeError):
        return cluster.curl("GET", "/readyz")["status"] == "ok"
    return False


def jobs_of(cluster: Cluster) -> JobLifecycle:
    """The jobs through the unix socket of the same Redis server."""
    store = FilesystemStore(cluster.work_dir / "artifacts")
    return JobLifecycle(redis.Redis(unix_socket_path=str(cluster.redis_socket)), store)


def wait_finished(cluster: Cluster, job_id: str, timeout_s: float) -> dict[str, Any]:
    return wait_for(
        lambda: (v := cluster.curl("GET", f"/v1/jobs/{job_id}"))["status"] in ("succeeded", "failed") and v,
        timeout_s,
        f"job {job_id} to finish",
        interval_s=0.5,
    )


def assert_one_set_of_artifacts(cluster: Cluster, job_id: str, chunk_count: int) -> None:
    names = [a["name"] for a in cluster.curl("GET", f"/v1/jobs/{job_id}/artifacts")["items"]]
    assert len(names) == len(set(names)) and names.count("image.exr") == 1
    assert sorted(n for n in names if n.startswith("chunks/")) == [
        f"chunks/{i}.npz" for i in range(chunk_count)
    ]
    job_dir = cluster.work_dir / "artifacts" / "jobs" / job_id
    assert not [p for p in job_dir.rglob(".*")], "temporary files left behind"


def test_chunks_are_split_across_both_worker_hosts(cluster: Cluster) -> None:
    created = cluster.curl("POST", "/v1/jobs", {"scene": tiny_scene(size_px=16, spp=16), "chunks": 4})
    final = wait_finished(cluster, created["id"], 90)
    assert final["status"] == "succeeded", final.get("error")
    assert {c["worker"] for c in final["chunks"]} == {"host1", "host2"}
    jobs = jobs_of(cluster)
    assert jobs.steps(created["id"]).completions() == {"0": 1, "1": 1, "2": 1, "3": 1, "merge": 1}
    # Both workers talk to Redis from their own host's address, not through loopback.
    clients = jobs.client.client_list()
    peers = {c["addr"].rsplit(":", 1)[0] for c in clients}
    assert {cluster.address("host1"), cluster.address("host2"), cluster.address("api")} <= peers
    assert_one_set_of_artifacts(cluster, created["id"], 4)


def test_cutting_off_a_worker_host_mid_chunk_still_succeeds_exactly_once(cluster: Cluster) -> None:
    """host2's link goes down while it renders; its heartbeat lapses (1 + 3 s), host1's maintenance pass
    (every 2 s) requeues the chunk and renders it. host2's horse may still finish writing the chunk file
    to the shared directory, but it cannot report to Redis, so its attempt never counts as a completion."""
    jobs = jobs_of(cluster)
    # Cornell box at 64x64 px: about spp / 700 s on 2 shared cores, so each 2048-spp chunk runs ~3 s.
    created = cluster.curl("POST", "/v1/jobs", {"scene": tiny_scene(size_px=64, spp=8192), "chunks": 4})
    job_id = created["id"]

    def host2_rendering() -> str | None:
        chunks = jobs.steps(job_id).chunks
        return next(
            (
                str(i)
                for i, chunk in enumerate(chunks)
                if chunk.worker == "host2" and chunk.status == "running" and chunk.progress > 0
            ),
            None,
        )

    index = wait_for(host2_rendering, 60, "host2 to render a chunk")
    _ip("-n", cluster.ns("host2"), "link", "set", "eth0", "down")
    final = wait_finished(cluster, job_id, 120)
    assert final["status"] == "succeeded", final.get("error")
    assert jobs.steps(job_id).completions() == {"0": 1, "1": 1, "2": 1, "3": 1, "merge": 1}
    assert final["chunks"][int(index)]["worker"] == "host1"
    assert final["chunks"][int(index)]["attempts"] == 2
    assert_one_set_of_artifacts(cluster, job_id, 4)
