"""The layout docs/design.md describes ("Stages", "What each stage may import"), checked on the
source: which module imports which, no import cycle, no module far over 500 lines without a
reason written at its top."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "pipeline"

PHYSICS = {"geometry", "constants", "colour", "daylight", "clearsky", "sky", "eclipse", "clouds", "ephemeris",
           "canopy", "grove_geometry", "rasteriser", "_raster", "_filter", "shadow", "albedo", "brdf", "camera",
           "foreground", "foreground_passes", "tree_detail", "composite"}
"""Modules of the method's mathematics: they know no config and no stage."""

BASE = {"errors", "paths", "io", "cache", "vocabulary", "cores", "__init__"}
"""Modules every layer may use."""

MAY_IMPORT = {
    "config": {"constants"},
    "resolve": {"config"} | PHYSICS,
    "inputs": {"config"} | PHYSICS,
    "framing": {"config", "inputs", "plan"} | PHYSICS,
    "plan": {"config", "resolve", "framing", "inputs"} | PHYSICS,
    "lighting": {"config", "plan", "inputs"} | PHYSICS,
    "cycle": {"config", "plan", "inputs"} | PHYSICS,
    "ground": {"config", "plan", "cycle", "inputs"} | PHYSICS,
    "frame": {"config", "plan", "lighting", "cycle", "ground", "inputs"} | PHYSICS,
    "runfolder": {"config"},
}
"""The stages and what each may import besides BASE (docs/design.md)."""


def imports(name: str, *, top_level_only: bool = False) -> set[str]:
    """The package's modules that ``pipeline/NAME.py`` imports (at module level only, or
    anywhere; ``if TYPE_CHECKING:`` blocks are annotations, not imports)."""
    tree = ast.parse((PACKAGE / f"{name}.py").read_text())
    found = set()

    def visit(node, top):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                continue
            if isinstance(child, ast.ImportFrom) and child.level == 1 and (top or not top_level_only):
                found.update([child.module] if child.module else [a.name for a in child.names])
            inner = isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
            visit(child, top and not inner)

    visit(tree, True)
    return {module.split(".")[0] for module in found} & {path.stem for path in PACKAGE.glob("*.py")}


MODULES = sorted(path.stem for path in PACKAGE.glob("*.py"))


@pytest.mark.parametrize("name", sorted(PHYSICS & set(MODULES)))
def test_the_physics_knows_no_config_and_no_stage(name):
    assert imports(name) <= PHYSICS | BASE, imports(name) - PHYSICS - BASE


def test_a_resume_with_nothing_to_do_imports_no_numpy():
    """The command, the config and the run folder's checks (docs/design.md): a resume that
    finds every frame done is decided without numpy, a stage or a physics module."""
    code = ("import sys, pipeline.cli, pipeline.config, pipeline.resolve, pipeline.runfolder; "
            "print(sorted(m for m in sys.modules if m == 'numpy' or m.startswith('pipeline.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=PACKAGE.parent).stdout
    assert "numpy" not in out and "pipeline.plan" not in out, out


@pytest.mark.parametrize("name", sorted(MAY_IMPORT))
def test_each_stage_imports_only_what_the_design_allows(name):
    assert imports(name) <= MAY_IMPORT[name] | BASE, imports(name) - MAY_IMPORT[name] - BASE


def test_there_is_no_import_cycle():
    graph = {name: imports(name, top_level_only=True) & set(MODULES) for name in MODULES}
    done, path, cycles = set(), [], []

    def visit(name):
        if name in path:
            cycles.append(" -> ".join(path[path.index(name):] + [name]))
            return
        if name in done:
            return
        path.append(name)
        for other in sorted(graph[name]):
            visit(other)
        path.pop()
        done.add(name)

    for name in MODULES:
        visit(name)
    assert cycles == []


@pytest.mark.parametrize("name", MODULES)
def test_a_long_module_says_why_at_its_top(name):
    """Over about 500 lines (550), the module docstring gives the reason ('Why one module')."""
    text = (PACKAGE / f"{name}.py").read_text()
    if text.count("\n") > 550:
        assert "Why one module" in (ast.get_docstring(ast.parse(text)) or ""), name


def test_the_docs_the_code_cites_exist():
    """Every 'docs/NAME.md, "Section"' a comment or docstring cites names a heading there."""
    import re

    docs = PACKAGE.parent / "docs"
    cited = set()
    for path in PACKAGE.glob("*.py"):
        text = " ".join(path.read_text().split())
        cited |= set(re.findall(r'docs/(\w+\.md), "([^"]+)"', text))
    assert cited
    for name, section in sorted(cited):
        headings = [line.lstrip("#").strip() for line in (docs / name).read_text().splitlines()
                    if line.startswith("#")]
        assert any(h.startswith(section) for h in headings), (name, section)
