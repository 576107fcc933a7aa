"""The layers: components never import orchestrator (an exported FMU ships only components/),
running an FMU does not load the FMU export (pythonfmu), no two modules and no two of orchestrator's
folders import each other, no component domain imports another."""

import ast
import subprocess
import sys
from pathlib import Path

from tests.conftest import needs

ROOT = Path(__file__).resolve().parents[2]


def imported_modules(tree: ast.AST) -> list[str]:
    names = []
    for node in ast.walk(tree):  # function-level imports too
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            names.append(node.module or "")
    return names


def test_no_component_module_imports_the_orchestrator():
    offenders = [
        f"{path.relative_to(ROOT)}: {name}"
        for path in sorted((ROOT / "components").rglob("*.py"))
        for name in imported_modules(ast.parse(path.read_text(), str(path)))
        if name == "orchestrator" or name.startswith("orchestrator.")
    ]
    assert not offenders, offenders


@needs("fmi", "type fmu")
def test_running_an_fmu_does_not_import_pythonfmu():
    imported = ROOT / "components" / "fmi" / "imported.py"
    assert "components.fmi.exported" not in imported_modules(ast.parse(imported.read_text()))
    code = (
        "import sys, components.fmi.imported, components.registry; "
        "loaded = [m for m in sys.modules if m.split('.')[0] == 'pythonfmu' or m == 'components.fmi.exported']; "
        "assert not loaded, loaded"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr


def project_modules() -> dict[str, Path]:
    modules = {}
    for top in ("components", "orchestrator"):
        for path in (ROOT / top).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports anywhere in it (function-level and TYPE_CHECKING too)."""
    modules = project_modules()
    graph = {}
    for module, path in modules.items():
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                edges |= {a.name for a in node.names if a.name in modules}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module in modules:
                submodules = {f"{node.module}.{a.name}" for a in node.names} & modules.keys()
                edges |= submodules or {node.module}
        graph[module] = edges - {module}
    return graph


def circles(graph: dict[str, set[str]]) -> list[str]:
    """Every path from a node back to itself, depth-first, as "a -> b -> a"."""
    found = []
    for start in graph:
        stack, seen = [(start, (start,))], set()
        while stack:
            node, path = stack.pop()
            for nxt in graph[node]:
                if nxt == start:
                    found.append(" -> ".join(path + (start,)))
                elif nxt not in seen:
                    seen.add(nxt)
                    stack.append((nxt, path + (nxt,)))
    return sorted(set(found))


def test_no_two_modules_import_each_other():
    found = circles(import_graph())
    assert not found, "\n".join(found)


def test_the_circle_check_finds_a_circle():
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [
        "a -> b -> c -> a",
        "b -> c -> a -> b",
        "c -> a -> b -> c",
    ]


def orchestrator_folder(module: str) -> str | None:
    """The folder of orchestrator/ a module is in (``run`` for orchestrator.run.engine), None outside them."""
    parts = module.split(".")
    return parts[1] if parts[0] == "orchestrator" and len(parts) > 2 else None


def folder_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """orchestrator's folders -> the other folders their modules import, wherever in a module the
    import is (one inside a function is no way around a layer)."""
    folders: dict[str, set[str]] = {}
    for module, imported in graph.items():
        folder = orchestrator_folder(module)
        if folder is not None:
            folders.setdefault(folder, set()).update(orchestrator_folder(m) for m in imported)
    return {folder: edges - {folder, None} for folder, edges in folders.items()}


def test_no_two_orchestrator_folders_import_each_other():
    """Each folder of orchestrator/ is a layer: config below run, hosts below config (the loop
    run -> config -> hosts -> run once hid behind imports inside functions)."""
    found = circles(folder_graph(import_graph()))
    assert not found, "folders importing each other (move what they share down a layer):\n" + "\n".join(found)


def test_the_folder_check_sees_an_import_inside_a_function():
    planted = {
        "orchestrator.run.engine": {"orchestrator.config.load"},
        "orchestrator.config.load": {"orchestrator.hosts.bus_config"},
        "orchestrator.hosts.bus_config": set(),
        "orchestrator.hosts.run_bus": {"orchestrator.run.runs"},  # as a function-level import would
        "orchestrator.cli": {"orchestrator.run.engine"},
        "components.bus": set(),
    }
    assert folder_graph(planted) == {"run": {"config"}, "config": {"hosts"}, "hosts": {"run"}}
    assert "config -> hosts -> run -> config" in circles(folder_graph(planted))
    source = "def open():\n    from orchestrator.run import runs\n"
    assert imported_modules(ast.parse(source)) == ["orchestrator.run"]


def private_imports(source: str, filename: str = "<source>") -> list[str]:
    """``from <project module> import _name`` in the source: a leading-underscore name that another
    module keeps private, used across the module boundary (dunder names such as __version__ are public)."""
    found = []
    imports = [node for node in ast.walk(ast.parse(source, filename)) if isinstance(node, ast.ImportFrom)]
    for node in sorted(imports, key=lambda node: node.lineno):  # function-level imports too
        module = node.module or ""
        if node.level == 0 and module.split(".")[0] not in ("components", "orchestrator"):
            continue
        found += [
            f"{filename}:{node.lineno}: from {'.' * node.level}{module} import {alias.name}"
            for alias in node.names
            if alias.name.startswith("_") and not alias.name.startswith("__")
        ]
    return found


def test_no_module_imports_a_private_name_of_another():
    offenders = [
        line
        for path in sorted(project_modules().values())
        for line in private_imports(path.read_text(), str(path.relative_to(ROOT)))
    ]
    assert not offenders, "private names imported across modules (make them public or move them):\n" + "\n".join(
        offenders
    )


def test_the_private_import_check_finds_one():
    planted = (
        "import os\nfrom os.path import _get_sep\nfrom components.units import to_si, _unit\n"
        "def f():\n    from orchestrator.run import _hidden\nfrom . import _sibling\nfrom components import __version__\n"
    )
    assert private_imports(planted, "planted.py") == [
        "planted.py:3: from components.units import _unit",
        "planted.py:5: from orchestrator.run import _hidden",
        "planted.py:6: from . import _sibling",
    ]


# the component domains: each keeps to itself. What several of them use lives below them: the
# modules at components/ (time scales, noise, rotations, constants, the ROS export's helpers) and
# the shared packages (space: the environment's models; robots: URDFs; viewer: the Rerun toolkit).
DOMAINS = ("orbit", "dynamics", "controller", "sensors", "camera", "estimators")
SHARED_BELOW_THE_DOMAINS = ("space", "robots")


def _package_imports(package: str) -> list[tuple[str, str]]:
    """(file, imported components.<X> package) of every import in components/<package>/."""
    found = []
    for path in sorted((ROOT / "components" / package).rglob("*.py")):
        for name in imported_modules(ast.parse(path.read_text(), str(path))):
            parts = name.split(".")
            if parts[0] == "components" and len(parts) > 1 and (ROOT / "components" / parts[1]).is_dir():
                found.append((str(path.relative_to(ROOT)), parts[1]))
    return found


def test_no_component_domain_imports_another():
    offenders = [
        f"{path}: components.{other}"
        for domain in DOMAINS
        for path, other in _package_imports(domain)
        if other in DOMAINS and other != domain
    ]
    assert not offenders, offenders


def test_the_shared_packages_import_no_component_domain():
    offenders = [
        f"{path}: components.{other}"
        for package in SHARED_BELOW_THE_DOMAINS
        for path, other in _package_imports(package)
        if other in DOMAINS
    ]
    assert not offenders, offenders
