"""The layers: components never import orchestrator (an exported FMU ships only components/),
and running an FMU does not load the FMU export (pythonfmu)."""
import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def imported_modules(tree: ast.AST) -> list[str]:
    names = []
    for node in ast.walk(tree):   # function-level imports too
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            names.append(node.module or "")
    return names


def test_no_component_module_imports_the_orchestrator():
    offenders = [f"{path.relative_to(ROOT)}: {name}"
                 for path in sorted((ROOT / "components").rglob("*.py"))
                 for name in imported_modules(ast.parse(path.read_text(), str(path)))
                 if name == "orchestrator" or name.startswith("orchestrator.")]
    assert not offenders, offenders


def test_running_an_fmu_does_not_import_pythonfmu():
    imported = ROOT / "components" / "fmi" / "imported.py"
    assert "components.fmi.exported" not in imported_modules(ast.parse(imported.read_text()))
    code = ("import sys, components.fmi.imported, components.registry; "
            "loaded = [m for m in sys.modules if m.split('.')[0] == 'pythonfmu' or m == 'components.fmi.exported']; "
            "assert not loaded, loaded")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
