"""Deployment files agree with the code: compose services and environment names, the Dockerfile's
essentials, and the configuration table in docs/configuration.md."""

from __future__ import annotations

import re

import yaml

from hgcore.settings import Settings
from tests.support import REPO_ROOT


def settings_env_names() -> set[str]:
    names = {"REDIS_URL" if n == "redis_url" else f"HGRENDER_{n.upper()}" for n in Settings.model_fields}
    return names  # Settings includes SceneLimits' fields


def test_compose_services_and_environment() -> None:
    compose = yaml.safe_load((REPO_ROOT / "docker-compose.yml").read_text())
    services = compose["services"]
    assert {"redis", "api", "worker", "scheduler"} <= set(services)
    assert "--appendonly" in services["redis"]["command"] and "yes" in services["redis"]["command"]
    assert services["worker"]["deploy"]["replicas"] >= 2
    images = {s.get("image") for name, s in services.items() if name != "redis"}
    assert images == {"hgrender:latest"}  # one image for api, workers and scheduler
    known = settings_env_names()
    for name in ("api", "worker", "scheduler"):
        environment = services[name]["environment"]
        assert set(environment) <= known, set(environment) - known
        assert any("/data" in volume for volume in services[name]["volumes"])  # shared artifacts
        assert environment["REDIS_URL"].startswith("redis://redis:")
    assert "healthcheck" in services["api"] and "healthcheck" in services["redis"]


def test_dockerfile_essentials() -> None:
    dockerfile = (REPO_ROOT / "Dockerfile").read_text()
    assert dockerfile.startswith("#") and "FROM python:3.11-slim-bookworm" in dockerfile
    assert "libllvm${LLVM_VERSION}" in dockerfile and "ARG LLVM_VERSION=19" in dockerfile
    assert "pip install ." in dockerfile
    assert re.search(r"^USER hgrender$", dockerfile, re.MULTILINE)
    assert "HEALTHCHECK" in dockerfile


def test_configuration_table_documents_every_setting() -> None:
    text = (REPO_ROOT / "docs" / "configuration.md").read_text()
    service_settings = text.split("\n## Command-line client")[0]  # the client's table follows
    documented = set(re.findall(r"^\| `([A-Z0-9_]+)` \|", service_settings, re.MULTILINE))
    assert documented == settings_env_names()
