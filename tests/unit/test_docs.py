"""The documentation stays true to the code: the site builds strictly, its generated pages are
current, the design's module map names every module, and the README's commands are CI's."""

import os
import re
import subprocess
import sys
from pathlib import Path

from tools import docs

ROOT = Path(__file__).resolve().parents[2]


def test_the_site_builds_with_warnings_as_errors(tmp_path):
    """mkdocs build --strict: every page in the nav, every relative link and anchor resolves."""
    build = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=240,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert build.returncode == 0, f"mkdocs build --strict failed:\n{build.stdout}\n{build.stderr}"
    assert (tmp_path / "site" / "reference" / "components" / "index.html").is_file()


def test_the_generated_pages_equal_what_the_code_gives():
    for page, make in docs.PAGES.items():
        assert page.read_text() == make(), f"{page.relative_to(ROOT)} is out of date: run python -m tools.docs"


def _module_map() -> str:
    design = (ROOT / "docs" / "design.md").read_text()
    return design.split("### Module map", 1)[1].split("\n## ", 1)[0]


def test_the_module_map_names_every_module_and_only_modules_that_exist():
    named = set(re.findall(r"`((?:orchestrator|components)/[\w/]+\.py)`", _module_map()))
    modules = {
        str(p.relative_to(ROOT))
        for package in ("orchestrator", "components")
        for p in (ROOT / package).rglob("*.py")
        if p.name != "__init__.py"
    }
    assert not modules - named, f"docs/design.md's module map lacks {sorted(modules - named)}"
    assert not named - modules, (
        f"docs/design.md's module map names modules that do not exist: {sorted(named - modules)}"
    )


def test_the_readme_gives_what_ci_runs_and_its_links_resolve():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]  # pip install -q -e ".[test]" && ...
    tests = 'pip install -e ".[test]" && ' + ci.split(" && ", 1)[1]
    assert tests in readme, f"the README's test command is not .ci/run's: {tests}"
    assert "pip install -e . && orchestrator run configs/humanoid_tracking.yaml --record runs/demo" in readme
    for target in re.findall(r"\]\(([^)\s]+)\)", readme):
        if not re.match(r"\w+://", target):
            assert (ROOT / target.split("#")[0]).exists(), f"README.md links to {target}, which does not exist"


def test_the_guide_shows_the_example_component_as_it_is():
    """The guide's first listing is components/examples/oscillator.py (its module docstring aside),
    so the code a newcomer copies is the code the tests run."""
    guide = (ROOT / "docs" / "guides" / "writing-a-component.md").read_text()
    listing = guide.split("```python\n", 1)[1].split("```", 1)[0]
    source = (ROOT / "components" / "examples" / "oscillator.py").read_text()
    code = source.split('"""', 2)[2].lstrip("\n")
    assert [line for line in listing.splitlines() if line] == [line for line in code.splitlines() if line]


def test_the_readmes_layout_lists_the_packages_on_disk():
    """The README's Layout block names every top-level folder and every subpackage of orchestrator/
    and components/ (``name/``), and nothing that is not there."""
    readme = (ROOT / "README.md").read_text()
    block = readme.split("## Layout\n\n```\n", 1)[1].split("```", 1)[0]
    entries: dict[str, set[str]] = {}
    current = None
    for line in block.splitlines():
        if line[:1].strip():
            current = line.split()[0].rstrip("/")
            entries[current] = set()
            line = line[len(current) + 1 :]
        entries[current] |= set(re.findall(r"\b([a-z_0-9]+)/", line))
    folders = {
        p.name
        for p in ROOT.iterdir()
        if p.is_dir()
        and not p.name.startswith(".")
        and not p.name.endswith(".egg-info")
        and p.name not in ("site", "runs", "build", "dist")
    }
    assert set(entries) == folders, f"README layout {sorted(entries)} against the folders {sorted(folders)}"
    for package in ("orchestrator", "components"):
        on_disk = {p.parent.name for p in (ROOT / package).glob("*/__init__.py")}
        assert entries[package] == on_disk, (
            f"README layout, {package}/: lists {sorted(entries[package])}, the subpackages are {sorted(on_disk)}"
        )
