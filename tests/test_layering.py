"""The package layering of ``docs/architecture.md``, as import-linter checks it in ``make lint``; no import
cycle between production modules; a worker that runs without the ``service`` package.

The project's own contracts must hold, and the same contracts must *fail* on a tree with a back-edge
(the shared core importing the service, the service importing Mitsuba), so a broken layer cannot pass;
likewise the cycle check must find a planted cycle.
"""

from __future__ import annotations

import ast
import subprocess
import sys
import tomllib
from pathlib import Path

import grimp
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


# ---- import cycles --------------------------------------------------------------------------------------


def import_cycles(graph: grimp.ImportGraph) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan): each is a set of modules
    that import each other around a cycle, lazily inside a function or not (grimp reads every import)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for imported in graph.find_modules_directly_imported_by(module):
            if imported not in index:
                visit(imported)
                low[module] = min(low[module], low[imported])
            elif imported in on_stack:
                low[module] = min(low[module], index[imported])
        if low[module] == index[module]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == module:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in sorted(graph.modules):
        if module not in index:
            visit(module)
    return cycles


def test_production_code_has_no_import_cycle() -> None:
    graph = grimp.build_graph(*PACKAGES, cache_dir=None)
    assert import_cycles(graph) == []


def test_a_cycle_is_found(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The check finds a cycle closed by an import inside a function (the kind that used to tie
    ``worker.tasks`` and ``worker.queue_worker`` together)."""
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "tasks.py").write_text("from pkg.queue_worker import PREFIX\n")
    (tmp_path / "pkg" / "queue_worker.py").write_text(
        "PREFIX = 1\ndef fail():\n    from pkg.tasks import x\n"
    )
    (tmp_path / "pkg" / "other.py").write_text("import pkg.tasks\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    graph = grimp.build_graph("pkg", cache_dir=None)
    assert import_cycles(graph) == [["pkg.queue_worker", "pkg.tasks"]]


# ---- a worker without the service -----------------------------------------------------------------------

WITHOUT_SERVICE = """
import importlib.abc, sys
class NoService(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "service" or name.startswith("service."):
            raise ModuleNotFoundError(f"No module named {name!r} (a worker image has no service/)")
        return None
sys.meta_path.insert(0, NoService())
from rq.utils import import_attribute
from hgcore.jobs.queue_graph import TASKS
import worker.preload, worker.queue_worker
for task in TASKS:
    import_attribute(task)
print("tasks:", len(TASKS))
"""


def test_a_worker_process_runs_without_the_service_package() -> None:
    """Every task a worker runs (the API names them by dotted string, which import-linter cannot see),
    the worker class and its preloading import with ``service`` absent, as in a worker-only image."""
    result = subprocess.run(
        [sys.executable, "-c", WITHOUT_SERVICE],
        cwd=REPO_ROOT,
        env={"PYTHONPATH": str(REPO_ROOT), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip() == "tasks: 4"


def test_no_test_module_imports_another_or_a_conftest() -> None:
    """Shared test code lives in ``tests/support`` (tests/README.md): a test module that imports another
    runs the other's module-level code and couples their fixtures; a conftest is pytest's, not a library."""
    import ast

    offenders = []
    for path in sorted((REPO_ROOT / "tests").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            names += [alias.name for alias in node.names] if isinstance(node, ast.Import) else []
            for name in names:
                last = name.rsplit(".", 1)[-1]
                if name.startswith("tests.") and (last.startswith("test_") or last == "conftest"):
                    offenders.append(f"{path.relative_to(REPO_ROOT)} imports {name}")
    assert offenders == []


# ---- importing reads no setting and changes nothing ---------------------------------------------------

IMPORT_EVERY_MODULE = """
import importlib, json, os, pkgutil, sys
packages = sys.argv[1:]
before = dict(os.environ)
imported = []
for package in packages:
    root = importlib.import_module(package)
    for info in pkgutil.walk_packages(root.__path__, package + "."):
        if info.name == "worker.render" or info.name.startswith("worker.render."):
            continue  # the renderer: imported only after an entry point configured Mitsuba
        importlib.import_module(info.name)
        imported.append(info.name)
changed = sorted(k for k in before.keys() | os.environ.keys() if before.get(k) != os.environ.get(k))
mitsuba = sys.modules.get("mitsuba")
print(json.dumps({
    "imported": imported,
    "environment_changed": changed,
    "mitsuba_variant": None if mitsuba is None else mitsuba.variant(),
}))
"""


def import_every_module(cwd: Path, *packages: str) -> dict:
    """Import every module of ``packages`` (but ``worker.render``) in a fresh interpreter: what it
    imported, the environment variables that changed meanwhile and Mitsuba's variant (None: none chosen
    or Mitsuba not imported)."""
    import json

    result = subprocess.run(
        [sys.executable, "-c", IMPORT_EVERY_MODULE, *packages],
        cwd=cwd,
        env={"PYTHONPATH": f"{cwd}:{REPO_ROOT}", "PATH": "/usr/bin:/bin", "HGRENDER_DATA_DIR": str(cwd)},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_importing_a_production_module_changes_no_setting_and_chooses_no_variant() -> None:
    """Every production module outside the renderer imports without touching ``os.environ`` or choosing
    a Mitsuba variant: settings are built by an entry point and passed down (docs/architecture.md)."""
    outcome = import_every_module(REPO_ROOT, *PACKAGES)
    assert {"service.main", "worker.tasks", "hgrender.cli.render", "schemas.validation"} <= set(
        outcome["imported"]
    )
    assert not any(name.startswith("worker.render") for name in outcome["imported"])
    assert outcome["environment_changed"] == []
    assert outcome["mitsuba_variant"] is None


@pytest.mark.parametrize(
    ("source", "found"),
    [
        ("import os\nos.environ['HGRENDER_SPP'] = '1'\n", "environment_changed"),
        ("import os\nos.environ.setdefault('DRJIT_LIBLLVM_PATH', '/x')\n", "environment_changed"),
        ("import mitsuba\nmitsuba.set_variant(mitsuba.variants()[0])\n", "mitsuba_variant"),
    ],
)
def test_an_import_side_effect_is_found(tmp_path: Path, source: str, found: str) -> None:
    """The check sees a module that writes the environment or chooses a variant when imported."""
    (tmp_path / "planted").mkdir()
    (tmp_path / "planted" / "__init__.py").write_text("")
    (tmp_path / "planted" / "quiet.py").write_text("import json\n")
    (tmp_path / "planted" / "loud.py").write_text(source)
    outcome = import_every_module(tmp_path, "planted")
    assert outcome["imported"] == ["planted.loud", "planted.quiet"]
    assert outcome[found]


# ---- the process's settings are passed down -------------------------------------------------------------


def _limits_parameters(trees: dict[str, ast.Module]) -> dict[str, int | None]:
    """Functions and classes of production code whose ``limits`` parameter has a default (a fallback to
    ``SceneLimits()`` from the environment, for tests and benchmarks): name → the parameter's position
    (None: keyword-only)."""
    found: dict[str, int | None] = {}
    for tree in trees.values():
        for owner in [tree, *(node for node in ast.walk(tree) if isinstance(node, ast.ClassDef))]:
            for function in owner.body:
                if not isinstance(function, ast.FunctionDef | ast.AsyncFunctionDef):
                    continue
                in_class = isinstance(owner, ast.ClassDef)
                if in_class and function.name != "__init__":
                    name, offset = function.name, 1  # a method: self, then its parameters
                elif in_class:
                    name, offset = owner.name, 1  # type: ignore[union-attr]  # the class is called
                else:
                    name, offset = function.name, 0
                arguments = function.args
                positional = [*arguments.posonlyargs, *arguments.args]
                with_default = positional[len(positional) - len(arguments.defaults) :]
                for index, argument in enumerate(positional):
                    if argument.arg == "limits" and argument in with_default:
                        found[name] = index - offset
                for argument, default in zip(arguments.kwonlyargs, arguments.kw_defaults, strict=True):
                    if argument.arg == "limits" and default is not None:
                        found[name] = None
    return found


def calls_without_limits(trees: dict[str, ast.Module]) -> list[str]:
    """Calls in ``trees`` of a function that falls back to the environment's limits, without limits."""
    parameters = _limits_parameters(trees)
    missing = []
    for path, tree in trees.items():
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call):
                continue
            name = getattr(node.func, "id", None) or getattr(node.func, "attr", None)
            if name not in parameters:
                continue
            position = parameters[name]
            passed = any(keyword.arg in ("limits", None) for keyword in node.keywords)
            passed |= any(isinstance(argument, ast.Starred) for argument in node.args)
            passed |= position is not None and len(node.args) > position
            if not passed:
                missing.append(f"{path}:{node.lineno} {name}(...)")
    return sorted(missing)


def _production_trees(root: Path) -> dict[str, ast.Module]:
    return {
        path.relative_to(root).as_posix(): ast.parse(path.read_text(), str(path))
        for package in PACKAGES
        for path in sorted((root / package).rglob("*.py"))
    }


def test_production_code_passes_its_settings_to_every_scene_check() -> None:
    """Validation, the USD importer, the image checks and the renderer's compile fall back to
    ``SceneLimits()`` (the environment) only for tests and benchmarks: every production call passes the
    process's settings, so a worker checks a scene against the limits it was started with."""
    trees = _production_trees(REPO_ROOT)
    parameters = _limits_parameters(trees)
    assert {"validate_scene", "with_film_overrides", "import_usd_isolated", "render_scene"} <= set(parameters)
    assert calls_without_limits(trees) == []


def test_a_call_without_limits_is_found() -> None:
    source = (
        "def validate_scene(data, limits=None): ...\n"
        "def render(scene, *, limits=None): ...\n"
        "class Compiler:\n"
        "    def __init__(self, mi, bundle_dir=None, limits=None): ...\n"
        "validate_scene({}, settings)\n"
        "validate_scene({})\n"
        "render(scene, limits=settings)\n"
        "render(scene)\n"
        "Compiler(mi, None, settings)\n"
        "Compiler(mi, bundle_dir)\n"
    )
    missing = calls_without_limits({"m.py": ast.parse(source)})
    assert missing == ["m.py:10 Compiler(...)", "m.py:6 validate_scene(...)", "m.py:8 render(...)"]


def imports_of_other_areas(root: Path) -> list[str]:
    """Imports of a helper of one test area (``tests/<area>/<module>.py``) from outside that area: the
    other areas, the top-level test modules and the benchmarks (shared helpers live in ``tests/support``)."""
    offenders = []
    paths = [*sorted((root / "tests").rglob("*.py")), *sorted((root / "bench").rglob("*.py"))]
    for path in paths:
        relative = path.relative_to(root)
        area = relative.parts[1] if relative.parts[0] == "tests" and len(relative.parts) > 2 else None
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = [alias.name for alias in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.module is not None:
                package = node.module.count(".") < 2  # ``from tests.render import scenes``: name the module
                names += [f"{node.module}.{a.name}" for a in node.names] if package else [node.module]
            for name in names:
                parts = name.split(".")
                if parts[0] == "tests" and len(parts) > 1 and parts[1] not in ("support", area):
                    offenders.append(f"{relative.as_posix()} imports {name}")
    return offenders


def test_a_helper_of_one_area_is_imported_only_there() -> None:
    """tests/README.md: helpers of one area stay beside its tests; what two areas (or a benchmark) share
    lives in ``tests/support``."""
    assert imports_of_other_areas(REPO_ROOT) == []


def test_an_import_of_another_areas_helper_is_found(tmp_path: Path) -> None:
    for folder in ("tests/render", "tests/integrator", "bench"):
        (tmp_path / folder).mkdir(parents=True)
    (tmp_path / "tests" / "render" / "test_a.py").write_text("from tests.render.exr import read\n")
    (tmp_path / "tests" / "integrator" / "test_b.py").write_text(
        "from tests.render import scenes\nimport tests.support.exr\n"
    )
    (tmp_path / "bench" / "bench_c.py").write_text("def f():\n    from tests.render.images import sky\n")
    assert imports_of_other_areas(tmp_path) == [
        "tests/integrator/test_b.py imports tests.render.scenes",
        "bench/bench_c.py imports tests.render.images",
    ]
