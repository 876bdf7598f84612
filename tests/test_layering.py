"""The package layering of ``docs/architecture.md``, as import-linter checks it in ``make lint``.

The project's own contracts must hold, and the same contracts must *fail* on a tree with a back-edge
(the shared core importing the service, the service importing Mitsuba), so a broken layer cannot pass.
"""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
LINT_IMPORTS = Path(sys.executable).parent / "lint-imports"
PACKAGES = ("hgcore", "schemas", "service", "worker", "hgrender")


def lint_imports(config: Path, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(LINT_IMPORTS), "--no-cache", str(config)],
        cwd=cwd,
        env={"PYTHONPATH": str(cwd), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=300,
    )


def _ini_list(key: str, values: list[str] | tuple[str, ...]) -> str:
    return f"{key} =\n" + "\n".join(f"    {value}" for value in values)


def test_the_project_keeps_its_layer_contracts() -> None:
    result = lint_imports(REPO_ROOT / "pyproject.toml", REPO_ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 broken" in result.stdout


@pytest.mark.parametrize(
    ("module", "source", "broken"),
    [
        ("hgcore/colour.py", "import service.api\n", "hgcore is not allowed to import service"),
        ("worker/tasks.py", "import service.jobs\n", "worker is not allowed to import service"),
        ("service/api.py", "import worker.tasks\n", "service is not allowed to import worker"),
        ("schemas/scene.py", "import worker.tasks\n", "schemas is not allowed to import worker"),
        ("service/api.py", "import drjit\n", "service.api -> drjit"),
        ("hgcore/colour.py", "def f():\n    import mitsuba\n", "hgcore.colour -> mitsuba"),
    ],
)
def test_a_back_edge_breaks_the_contracts(tmp_path: Path, module: str, source: str, broken: str) -> None:
    """A miniature tree with the project's packages and one forbidden import, checked with the project's
    own contracts (only the ignore list of known edges is dropped)."""
    config = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    for package in PACKAGES:
        (tmp_path / package).mkdir()
        (tmp_path / package / "__init__.py").write_text("")
    for name in ("drjit", "mitsuba"):  # stand-ins for the external packages
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text("")
    (tmp_path / "worker" / "tasks.py").write_text("")
    (tmp_path / "service" / "jobs.py").write_text("")
    (tmp_path / "service" / "api.py").write_text("")
    (tmp_path / module).write_text(source)
    lines = ["[importlinter]", _ini_list("root_packages", PACKAGES), "include_external_packages = True"]
    for index, contract in enumerate(config["contracts"]):
        lines += [
            "",
            f"[importlinter:contract:{index}]",
            f"name = {contract['name']}",
            f"type = {contract['type']}",
        ]
        for key in ("layers", "source_modules", "forbidden_modules"):
            if key in contract:
                lines.append(_ini_list(key, contract[key]))
    (tmp_path / "contracts.ini").write_text("\n".join(lines) + "\n")
    result = lint_imports(tmp_path / "contracts.ini", tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert broken in result.stdout
