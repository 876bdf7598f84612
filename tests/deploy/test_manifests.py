"""Kubernetes manifests (deploy/), compose and Dockerfile agree with the code (issue 8).

The kustomize base, the dev overlay and the components are rendered with ``kubectl kustomize`` (skipped
where kubectl is not installed; the raw YAML is parsed with PyYAML regardless), validated against the
Kubernetes OpenAPI schemas (kubernetes-validate) and checked: required fields, one hgrender image, probes
on /readyz and /healthz, resources, non-root security contexts, the worker's termination grace against
its shutdown grace, KEDA triggers on RQ's queue lists, selectors that select something, and every
environment variable name known to ``Settings`` (which includes ``SceneLimits``).
"""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from hgcore.settings import QUEUE_NAMES, Settings
from hgrender.cli import build_parser

REPO_ROOT = Path(__file__).resolve().parents[2]
DEPLOY_DIR = REPO_ROOT / "deploy"
KUBECTL = shutil.which("kubectl")

BOTO3_ENV_NAMES = frozenset({"AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY", "AWS_SESSION_TOKEN"})
"""Read by boto3 for the S3 store (docs/configuration.md, notes), not by Settings."""

RENDERER_ENV_NAMES = frozenset({"HGRENDER_VARIANT"})
"""Read by ``worker.mitsuba_setup`` (the renderer's Mitsuba variant), documented in configuration.md."""

RUNTIME_ENV_NAMES = frozenset({"NVIDIA_DRIVER_CAPABILITIES"})
"""Read by the NVIDIA container runtime on GPU nodes, not by hgrender."""

WORKLOAD_KINDS = ("Deployment", "StatefulSet")


def known_env_names() -> set[str]:
    """Environment names of every setting (the rows of docs/configuration.md's table)."""
    names = {"REDIS_URL" if n == "redis_url" else f"HGRENDER_{n.upper()}" for n in Settings.model_fields}
    return names


def kustomize(tmp_path: Path, resources: list[str], components: list[str]) -> list[dict[str, Any]]:
    """``kubectl kustomize`` of a throw-away kustomization that includes the given repo directories."""
    if KUBECTL is None:
        pytest.skip("kubectl (with built-in kustomize) is not installed")
    root = tmp_path / "kustomization"
    root.mkdir()

    def rel(path: str) -> str:
        return os.path.relpath(DEPLOY_DIR / path, root)

    (root / "kustomization.yaml").write_text(
        yaml.safe_dump(
            {
                "apiVersion": "kustomize.config.k8s.io/v1beta1",
                "kind": "Kustomization",
                "resources": [rel(r) for r in resources],
                "components": [rel(c) for c in components],
            }
        )
    )
    built = subprocess.run(
        [KUBECTL, "kustomize", "--load-restrictor=LoadRestrictionsNone", str(root)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert built.returncode == 0, built.stderr
    return [doc for doc in yaml.safe_load_all(built.stdout) if doc]


VARIANTS = {
    "base": (["base"], []),
    "dev": (["overlays/dev"], []),
    "dev+hpa+s3": (["overlays/dev"], ["components/hpa-fallback", "components/s3-store"]),
    "base+gpu": (["base"], ["components/gpu-workers"]),
}


@pytest.fixture(params=list(VARIANTS), scope="module")
def rendered(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    resources, components = VARIANTS[request.param]
    docs = kustomize(tmp_path_factory.mktemp(request.param), resources, components)
    return {"name": request.param, "docs": docs, "components": components}


def by_kind(docs: list[dict[str, Any]], kind: str) -> dict[str, dict[str, Any]]:
    return {d["metadata"]["name"]: d for d in docs if d["kind"] == kind}


def pod_spec(workload: dict[str, Any]) -> dict[str, Any]:
    return workload["spec"]["template"]["spec"]


def hgrender_containers(docs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [
        c
        for d in docs
        if d["kind"] in WORKLOAD_KINDS
        for c in pod_spec(d)["containers"]
        if c["image"].split(":")[0] == "hgrender"
    ]


def settings_from(env: dict[str, str], monkeypatch: pytest.MonkeyPatch) -> Settings:
    """The Settings a container with exactly this environment would read (validates every value)."""
    for name in list(os.environ):
        if name.startswith("HGRENDER_") or name == "REDIS_URL":
            monkeypatch.delenv(name)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    return Settings()


def configured_env(docs: list[dict[str, Any]]) -> dict[str, str]:
    """The ConfigMap plus Secret environment every hgrender container gets through ``envFrom``."""
    config = by_kind(docs, "ConfigMap")
    secrets = by_kind(docs, "Secret")
    (config_map,) = [c for n, c in config.items() if n.startswith("hgrender-config")]
    (secret,) = [s for n, s in secrets.items() if n.startswith("hgrender-secrets")]
    decoded = {k: base64.b64decode(v).decode() for k, v in secret.get("data", {}).items()}
    return config_map["data"] | decoded


def test_rendered_resources_validate_against_the_kubernetes_schemas(rendered: dict[str, Any]) -> None:
    """Strict OpenAPI-schema validation (kubernetes-validate, offline; unknown fields are errors) of
    every built-in kind; KEDA's ScaledObject has no bundled schema and is checked field by field below."""
    kubernetes_validate = pytest.importorskip("kubernetes_validate")
    version = kubernetes_validate.latest_version()
    for doc in rendered["docs"]:
        if doc["kind"] == "ScaledObject":
            continue
        kubernetes_validate.validate(doc, version, strict=True)
    # The check bites: a misspelt field in a copy of the worker Deployment is rejected.
    worker = json.loads(json.dumps(by_kind(rendered["docs"], "Deployment")["hgrender-worker"]))
    pod_spec(worker)["terminationGracePeriod"] = 60
    with pytest.raises(kubernetes_validate.ValidationError):
        kubernetes_validate.validate(worker, version, strict=True)


def test_raw_yaml_parses_and_every_resource_is_named() -> None:
    files = sorted(DEPLOY_DIR.rglob("*.yaml"))
    assert len(files) >= 10
    for path in files:
        for doc in yaml.safe_load_all(path.read_text()):
            assert doc and "apiVersion" in doc and "kind" in doc, path
            if doc["kind"] not in ("Kustomization", "Component"):
                assert doc["metadata"]["name"], path


def test_workloads_have_image_probes_resources_and_non_root_security(rendered: dict[str, Any]) -> None:
    docs = rendered["docs"]
    workloads = {d["metadata"]["name"]: d for d in docs if d["kind"] in WORKLOAD_KINDS}
    assert set(workloads) == {"hgrender-api", "hgrender-worker", "hgrender-scheduler", "hgrender-redis"}
    images = {c["image"] for c in hgrender_containers(docs)}
    assert len(images) == 1, images  # one image for API, workers and scheduler, as in compose
    for name, workload in workloads.items():
        spec = pod_spec(workload)
        assert spec["securityContext"]["runAsNonRoot"] is True, name
        assert spec["securityContext"]["runAsUser"] > 0, name
        assert spec["securityContext"]["seccompProfile"]["type"] == "RuntimeDefault", name
        for container in spec["containers"]:
            security = container["securityContext"]
            assert security["allowPrivilegeEscalation"] is False, name
            assert security["capabilities"]["drop"] == ["ALL"], name
            for bound in ("requests", "limits"):
                assert {"cpu", "memory"} <= set(container["resources"][bound]), (name, bound)
            assert "livenessProbe" in container, name
        # A read-only root file system needs every path the code writes to mounted.
        mounts = {m["mountPath"] for c in spec["containers"] for m in c.get("volumeMounts", [])}
        assert "/tmp" in mounts or name == "hgrender-redis", name
    api = pod_spec(workloads["hgrender-api"])["containers"][0]
    port_names = {p["name"]: p["containerPort"] for p in api["ports"]}
    assert api["readinessProbe"]["httpGet"] == {"path": "/readyz", "port": "http"}
    assert api["livenessProbe"]["httpGet"] == {"path": "/healthz", "port": "http"}
    assert api["command"][:2] == ["hgrender", "serve"]
    assert api["command"][api["command"].index("--port") + 1] == str(port_names["http"])
    assert api["command"][api["command"].index("--host") + 1] == "0.0.0.0"
    assert pod_spec(workloads["hgrender-worker"])["containers"][0]["command"] == ["hgrender", "worker"]
    assert pod_spec(workloads["hgrender-scheduler"])["containers"][0]["command"] == ["hgrender", "scheduler"]
    commands = build_parser()._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    assert {"serve", "worker", "scheduler"} <= set(commands)


def test_every_environment_name_is_a_setting_and_values_validate(
    rendered: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    docs = rendered["docs"]
    env = configured_env(docs)
    container_env = {e["name"] for c in hgrender_containers(docs) for e in c.get("env", [])}
    unknown = (set(env) | container_env) - known_env_names() - BOTO3_ENV_NAMES
    unknown -= RENDERER_ENV_NAMES | RUNTIME_ENV_NAMES
    assert not unknown, f"not settings: {unknown}"
    for container in hgrender_containers(docs):
        refs = [r.get("configMapRef", r.get("secretRef"))["name"] for r in container["envFrom"]]
        assert any(r.startswith("hgrender-config") for r in refs)
        assert any(r.startswith("hgrender-secrets") for r in refs)
    settings = settings_from(env, monkeypatch)
    assert settings.workers == 0 and settings.regression_scheduler is False  # own Deployments do those
    assert settings.redis_url is not None
    redis_service = by_kind(docs, "Service")
    if "hgrender-redis" in by_kind(docs, "StatefulSet"):
        assert settings.redis_url.startswith("redis://hgrender-redis:")
        assert "hgrender-redis" in redis_service
    if "components/s3-store" in rendered["components"]:
        assert settings.store == "s3" and settings.s3_bucket


def test_renderer_environment_names_are_read_and_documented() -> None:
    configuration = (REPO_ROOT / "docs" / "configuration.md").read_text()
    for name in RENDERER_ENV_NAMES:
        assert name in (REPO_ROOT / "worker" / "mitsuba_setup.py").read_text()
        assert f"`{name}`" in configuration
    for name in BOTO3_ENV_NAMES - {"AWS_SESSION_TOKEN"}:
        assert f"`{name}`" in configuration


def test_gpu_workers_request_a_gpu_and_a_cuda_variant(tmp_path: Path) -> None:
    from worker.mitsuba_setup import SUPPORTED_VARIANTS

    docs = kustomize(tmp_path, ["base"], ["components/gpu-workers"])
    worker = by_kind(docs, "Deployment")["hgrender-worker"]
    (container,) = pod_spec(worker)["containers"]
    env = {e["name"]: e["value"] for e in container["env"]}
    assert env["HGRENDER_VARIANT"] in SUPPORTED_VARIANTS and env["HGRENDER_VARIANT"].startswith("cuda_")
    assert container["resources"]["limits"]["nvidia.com/gpu"] == 1
    assert container["envFrom"] and container["command"] == ["hgrender", "worker"]  # merged, not replaced
    assert any(t["key"] == "nvidia.com/gpu" for t in pod_spec(worker)["tolerations"])


def test_worker_termination_grace_covers_the_shutdown_grace(
    rendered: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The kubelet SIGKILLs a pod terminationGracePeriodSeconds after SIGTERM. The worker hands its chunk
    back at the first heartbeat tick after the grace, i.e. by grace + monitoring interval; 5 s more
    leave room to requeue and deregister."""
    docs = rendered["docs"]
    settings = settings_from(configured_env(docs), monkeypatch)
    worker = by_kind(docs, "Deployment")["hgrender-worker"]
    termination_s = pod_spec(worker)["terminationGracePeriodSeconds"]
    assert termination_s >= settings.worker_shutdown_grace_s + settings.worker_monitoring_interval_s + 5
    assert worker["spec"]["strategy"]["rollingUpdate"]["maxUnavailable"] == 0


def test_redis_persists_with_aof_on_a_claim(rendered: dict[str, Any]) -> None:
    redis = by_kind(rendered["docs"], "StatefulSet")["hgrender-redis"]
    container = pod_spec(redis)["containers"][0]
    args = container["args"]
    assert args[args.index("--appendonly") + 1] == "yes"
    data_dir = args[args.index("--dir") + 1]
    (claim,) = redis["spec"]["volumeClaimTemplates"]
    assert {"name": claim["metadata"]["name"], "mountPath": data_dir} in container["volumeMounts"]


def test_autoscaling_watches_every_rq_queue(rendered: dict[str, Any]) -> None:
    docs = rendered["docs"]
    scaled = by_kind(docs, "ScaledObject")
    if "components/hpa-fallback" in rendered["components"]:
        assert not scaled  # replaced, not doubled: two autoscalers would fight over the replicas
        hpa = by_kind(docs, "HorizontalPodAutoscaler")["hgrender-worker"]
        assert hpa["spec"]["scaleTargetRef"]["name"] == "hgrender-worker"
        return
    scaled_object = scaled["hgrender-worker"]
    assert scaled_object["spec"]["scaleTargetRef"]["name"] == "hgrender-worker"
    triggers = scaled_object["spec"]["triggers"]
    assert sorted(t["metadata"]["listName"] for t in triggers) == sorted(f"rq:queue:{q}" for q in QUEUE_NAMES)
    namespace = by_kind(docs, "Namespace")
    (namespace_name,) = namespace
    for trigger in triggers:
        assert trigger["type"] == "redis"
        # KEDA's operator runs in its own namespace: the address must be fully qualified.
        host, port = trigger["metadata"]["address"].rsplit(":", 1)
        assert host == f"hgrender-redis.{namespace_name}.svc.cluster.local" and port == "6379"
        assert int(trigger["metadata"]["listLength"]) >= 1


def test_selectors_claims_and_backends_resolve(rendered: dict[str, Any]) -> None:
    docs = rendered["docs"]
    pod_labels = [d["spec"]["template"]["metadata"]["labels"] for d in docs if d["kind"] in WORKLOAD_KINDS]

    def selects(selector: dict[str, str]) -> bool:
        return any(selector.items() <= labels.items() for labels in pod_labels)

    for workload in (d for d in docs if d["kind"] in WORKLOAD_KINDS):
        assert workload["spec"]["selector"]["matchLabels"].items() <= (
            workload["spec"]["template"]["metadata"]["labels"].items()
        )
    for name, service in by_kind(docs, "Service").items():
        assert selects(service["spec"]["selector"]), name
    pdbs = by_kind(docs, "PodDisruptionBudget")
    assert {"hgrender-api", "hgrender-worker"} <= set(pdbs)
    for name, pdb in pdbs.items():
        assert selects(pdb["spec"]["selector"]["matchLabels"]), name
    claims = set(by_kind(docs, "PersistentVolumeClaim"))
    for workload in (d for d in docs if d["kind"] in WORKLOAD_KINDS):
        for volume in pod_spec(workload).get("volumes", []):
            if "persistentVolumeClaim" in volume:
                assert volume["persistentVolumeClaim"]["claimName"] in claims
    services = by_kind(docs, "Service")
    for ingress in by_kind(docs, "Ingress").values():
        for rule in ingress["spec"]["rules"]:
            for path in rule["http"]["paths"]:
                backend = path["backend"]["service"]
                ports = {p["name"] for p in services[backend["name"]]["spec"]["ports"]}
                assert backend["port"]["name"] in ports


def test_compose_and_kubernetes_set_the_same_values() -> None:
    """One configuration for both: where compose and the base ConfigMap set the same name, they agree
    (REDIS_URL differs only by the Redis host name)."""
    compose = yaml.safe_load((REPO_ROOT / "docker-compose.yml").read_text())
    kustomization = yaml.safe_load((DEPLOY_DIR / "base" / "kustomization.yaml").read_text())
    (config,) = [g for g in kustomization["configMapGenerator"] if g["name"] == "hgrender-config"]
    k8s_env = dict(item.split("=", 1) for item in config["literals"])
    for service_name in ("api", "worker", "scheduler"):
        compose_env = {k: str(v) for k, v in compose["services"][service_name]["environment"].items()}
        assert set(compose_env) <= known_env_names()
        shared = set(compose_env) & set(k8s_env)
        assert {"HGRENDER_STORE", "HGRENDER_WORKER_SHUTDOWN_GRACE_S"} <= shared
        assert {k: compose_env[k] for k in shared} == {k: k8s_env[k] for k in shared}
    grace_s = int(k8s_env["HGRENDER_WORKER_SHUTDOWN_GRACE_S"])
    monitoring_s = int(k8s_env["HGRENDER_WORKER_MONITORING_INTERVAL_S"])
    stop_grace = compose["services"]["worker"]["stop_grace_period"]
    assert int(stop_grace.removesuffix("s")) >= grace_s + monitoring_s + 5


def test_dockerfile_user_and_copied_packages_match(rendered: dict[str, Any]) -> None:
    """The pods' runAsUser is the Dockerfile's user, and the Dockerfile copies every package that
    pyproject's setuptools ``include`` installs, plus web/ for the viewer (found via PYTHONPATH=/app)."""
    dockerfile = (REPO_ROOT / "Dockerfile").read_text()
    uid = int(re.search(r"useradd .*--uid (\d+) hgrender", dockerfile).group(1))  # type: ignore[union-attr]
    for container_pod in (d for d in rendered["docs"] if d["kind"] == "Deployment"):
        assert pod_spec(container_pod)["securityContext"]["runAsUser"] == uid
    copied = set(re.findall(r"^COPY (\S+) \./\1$", dockerfile, re.MULTILINE))
    pyproject = (REPO_ROOT / "pyproject.toml").read_text()
    packages = {
        p.rstrip("*")
        for p in re.search(r"include = \[(.*?)\]", pyproject).group(1).replace('"', "").split(", ")
    }  # type: ignore[union-attr]
    assert packages | {"web"} <= copied
    assert "PYTHONPATH=/app" in dockerfile and re.search(r"^WORKDIR /app$", dockerfile, re.MULTILINE)


def test_dockerfile_install_step_builds_from_the_copied_files_only(tmp_path: Path) -> None:
    """``pip install .`` in the image sees only the COPY'd files: run setuptools' build of exactly those
    (``egg_info`` + ``build_py``, what pip's wheel build does before zipping; without dependencies, since
    downloading Mitsuba and friends into a clean venv is not cheap) and check the result has every package,
    the schemas' data files and the console script. With PYTHONPATH at that copy (the image's
    ``PYTHONPATH=/app``), the API's viewer directory resolves inside it."""
    dockerfile = (REPO_ROOT / "Dockerfile").read_text()
    context = tmp_path / "app"
    context.mkdir()
    for line in re.findall(r"^COPY (.+)$", dockerfile, re.MULTILINE):
        *sources, _destination = line.split()
        for source in sources:
            path = REPO_ROOT / source
            target = context / source
            if path.is_dir():
                shutil.copytree(path, target, ignore=shutil.ignore_patterns("__pycache__", "node_modules"))
            else:
                shutil.copy2(path, target)
    build_lib, egg_base = tmp_path / "lib", tmp_path / "egg"
    egg_base.mkdir()
    setup = "import setuptools; setuptools.setup()"
    built = subprocess.run(
        [
            sys.executable,
            "-c",
            setup,
            "egg_info",
            "--egg-base",
            str(egg_base),
            "build_py",
            "-d",
            str(build_lib),
        ],
        cwd=context,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert built.returncode == 0, built.stderr
    for module in ("hgrender/cli/__init__.py", "service/main.py", "worker/tasks.py", "hgcore/settings.py"):
        assert (build_lib / module).is_file(), module
    assert list((build_lib / "schemas" / "examples").glob("*.json"))
    (entry_points,) = egg_base.glob("*.egg-info/entry_points.txt")
    assert "hgrender = hgrender.cli:main" in entry_points.read_text()
    web_dir = subprocess.run(
        [sys.executable, "-c", "from service.api.routes.web import WEB_DIR; print(WEB_DIR)"],
        env={**os.environ, "PYTHONPATH": str(context)},
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert web_dir.returncode == 0, web_dir.stderr
    assert Path(web_dir.stdout.strip()) == context / "web"
    assert (context / "web" / "index.html").is_file()
