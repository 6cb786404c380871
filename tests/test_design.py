"""The layout docs/design.md describes ("Stages", "What each stage may import"), checked on the
source: which module imports which (the table in the docs, parsed), no import cycle, no module
over 700 lines."""

import ast
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "pipeline"

DESIGN = PACKAGE.parent / "docs" / "design.md"

MOST_LINES = 700
"""No module of pipeline/ is longer (docs/design.md, "Modules")."""


def import_table(text: str) -> dict[str, set[str]]:
    """docs/design.md's table "What each stage may import", as {module: the modules it may import}.

    A row names its modules in backticks in the first cell and what they may import in the
    second: modules in backticks, and the words "the physics" (every module of the row that
    begins "the physics"), "the shared modules" (those of the row that begins "the shared") and
    "anything" (every module). Every module may import the shared modules."""
    section = text.split("### What each stage may import", 1)[1].split("\n#", 1)[0]
    rows = [line.split("|")[1:3] for line in section.splitlines() if line.startswith("| ") and "`" in line]
    groups = {}
    for left, _right in rows:
        for word in ("the physics", "the shared"):
            if left.strip().startswith(word):
                groups[word] = set(re.findall(r"`(\w+)`", left))
    every = set().union(*(set(re.findall(r"`(\w+)`", left)) for left, _ in rows))
    table = {}
    for left, right in rows:
        allowed = set(re.findall(r"`(\w+)`", right)) | groups.get("the shared", set())
        if "the physics" in right:
            allowed |= groups["the physics"]
        if "anything" in right:
            allowed |= every
        for name in re.findall(r"`(\w+)`", left):
            table[name] = allowed
    return table


def imports(name: str, *, top_level_only: bool = False, package: Path = PACKAGE) -> set[str]:
    """The package's modules that ``pipeline/NAME.py`` imports (at module level only, or
    anywhere), relative (``from . import x``, ``from .x import y``) or absolute (``import
    pipeline.x``, ``from pipeline import x``); ``if TYPE_CHECKING:`` blocks are annotations, not
    imports."""
    tree = ast.parse((package / f"{name}.py").read_text())
    found = set()

    def visit(node, top):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                continue
            if top or not top_level_only:
                if isinstance(child, ast.ImportFrom):
                    module = child.module or ""
                    if child.level == 1 or module == "pipeline" or module.startswith("pipeline."):
                        inner = module.removeprefix("pipeline").lstrip(".") if child.level == 0 else module
                        found.update([inner] if inner else [a.name for a in child.names])
                elif isinstance(child, ast.Import):
                    found.update(a.name.split(".", 2)[1] for a in child.names if a.name.startswith("pipeline."))
            inner = isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
            visit(child, top and not inner)

    visit(tree, True)
    return {module.split(".")[0] for module in found} & {path.stem for path in package.glob("*.py")}


def violations(package: Path = PACKAGE) -> list[str]:
    """Every import of a module of ``package`` that docs/design.md's table does not allow, and
    every module the table does not place, as 'a imports b'."""
    table = import_table(DESIGN.read_text())
    found = []
    for path in sorted(package.glob("*.py")):
        name = path.stem
        if name not in table:
            found.append(f"{name} is not in the table")
            continue
        found += [f"{name} imports {other}" for other in sorted(imports(name, package=package) - table[name] - {name})]
    return found


MODULES = sorted(path.stem for path in PACKAGE.glob("*.py"))


def test_every_import_is_one_the_design_table_allows():
    assert violations() == []


def test_every_module_has_its_row_in_the_modules_table():
    """docs/design.md, "Modules", says what each module of pipeline/ owns."""
    section = DESIGN.read_text().split("## Modules", 1)[1].split("\n## ", 1)[0]
    listed = {name for line in section.splitlines() if line.startswith("| ")
              for name in re.findall(r"`(\w+)\.py`", line.split("|")[1])}
    assert set(MODULES) - {"__init__"} - listed == set()


def test_the_table_check_fails_on_a_low_module_importing_a_high_one(tmp_path):
    """A copy of the package where geometry.py imports cli (docs/design.md's example) fails."""
    copy = tmp_path / "pipeline"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "geometry.py").write_text((copy / "geometry.py").read_text() + "\nfrom pipeline import cli\n")
    assert violations(copy) == ["geometry imports cli"]


def test_a_resume_with_nothing_to_do_imports_no_numpy():
    """The command, the config and the run folder's checks (docs/design.md): a resume that
    finds every frame done is decided without numpy, a stage or a physics module."""
    code = ("import sys, pipeline.cli, pipeline.config, pipeline.resolve, pipeline.runrecord; "
            "print(sorted(m for m in sys.modules if m == 'numpy' or m.startswith('pipeline.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=PACKAGE.parent).stdout
    assert "numpy" not in out and "pipeline.plan" not in out, out


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
def test_no_module_is_longer_than_the_most(name):
    assert (PACKAGE / f"{name}.py").read_text().count("\n") <= MOST_LINES


def test_the_docs_the_code_cites_exist():
    """Every 'docs/NAME.md, "Section"' a comment or docstring cites names a heading there."""
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
