"""The layout docs/design.md describes ("Packages", "What each package may import"), checked on the
source: which package imports which (the table in the docs, parsed), no private name taken from
another module, no import cycle, no module over 700 lines, no function over 80 lines."""

import ast
import functools
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

MOST_FUNCTION_LINES = 80
"""No function of pipeline/ is longer, its decorators and docstring included (docs/design.md, "Modules")."""


def import_table(text: str) -> dict[str, set[str]]:
    """docs/design.md's table "What each package may import", as {package: the packages it may import}.

    A row names one subpackage of pipeline/ in backticks in its first cell and what it may import in
    the second: packages in backticks, or the word "anything" (every package). Every module may import
    the modules of its own package and ``pipeline`` itself (its ``__version__``)."""
    section = text.split("### What each package may import", 1)[1].split("\n#", 1)[0]
    rows = [line.split("|")[1:3] for line in section.splitlines() if line.startswith("| ") and "`" in line]
    every = {re.findall(r"`(\w+)`", left)[0] for left, _ in rows}
    table = {}
    for left, right in rows:
        name = re.findall(r"`(\w+)`", left)[0]
        table[name] = (every if "anything" in right else set(re.findall(r"`(\w+)`", right))) | {name}
    return table


def module_names(package: Path = PACKAGE) -> dict[Path, str]:
    """Every module of ``package`` as its dotted name below it: ``sky.eclipse``, ``stages.frame``;
    a subpackage's ``__init__`` as the subpackage's name, the top ``__init__`` as ``""``."""
    names = {}
    for path in sorted(package.rglob("*.py")):
        parts = path.relative_to(package).with_suffix("").parts
        names[path] = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
    return names


def _absolute(node: ast.ImportFrom, me: str, is_init: bool) -> str:
    """The module an ``ImportFrom`` names, dotted below pipeline (``""`` for pipeline itself), or
    None when it is outside pipeline."""
    if node.level == 0:
        module = node.module or ""
        if module != "pipeline" and not module.startswith("pipeline."):
            return None
        return module.removeprefix("pipeline").lstrip(".")
    parts = me.split(".") if me else []
    base = parts if is_init else parts[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


@functools.cache
def _tree(text: str) -> ast.Module:
    """A module's source parsed, once for the session (about 10 ms a module; the checks below
    read the same unchanged modules several times over, and never change a tree)."""
    return ast.parse(text)


def imports(path: Path, *, top_level_only: bool = False, package: Path = PACKAGE,
            names: dict[Path, str] | None = None) -> dict[str, set[str]]:
    """What the module at ``path`` takes from the package: {module imported (dotted below pipeline):
    the names taken from it, and the attributes read on it}. Relative or absolute imports, at module
    level only or anywhere; ``if TYPE_CHECKING:`` blocks are annotations, not imports. ``names``:
    ``module_names(package)``, when the caller has it."""
    names = names or module_names(package)
    found = _imports(path.read_text(), names[path], path.name == "__init__.py", top_level_only,
                     frozenset(names.values()))
    return {module: set(taken) for module, taken in found.items()}


@functools.cache
def _imports(text: str, me: str, is_init: bool, top_level_only: bool,
             known: frozenset[str]) -> dict[str, frozenset[str]]:
    """``imports`` of a module's text, found once for each text, name and package."""
    tree = _tree(text)
    found: dict[str, set[str]] = {}
    aliases = {}

    def take(module, name=None):
        found.setdefault(module, set())
        if name:
            found[module].add(name)

    def visit(node, top):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                continue
            if top or not top_level_only:
                if isinstance(child, ast.ImportFrom):
                    source = _absolute(child, me, is_init)
                    if source is not None:
                        for alias in child.names:
                            inner = f"{source}.{alias.name}".lstrip(".")
                            if inner in known:
                                take(inner)
                                aliases[alias.asname or alias.name] = inner
                            else:
                                take(source, alias.name)
                elif isinstance(child, ast.Import):
                    for alias in child.names:
                        if alias.name.startswith("pipeline."):
                            inner = alias.name.removeprefix("pipeline.")
                            take(inner)
                            if alias.asname:
                                aliases[alias.asname] = inner
            inner = isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
            visit(child, top and not inner)

    visit(tree, True)
    if not top_level_only:
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
                take(aliases[node.value.id], node.attr)
    return {module: frozenset(taken) for module, taken in found.items() if module in known and module != me}


def violations(package: Path = PACKAGE) -> list[str]:
    """Every import of a module of ``package`` that docs/design.md's table does not allow, and every
    subpackage the table does not place, as 'a.b imports c.d'."""
    table = import_table(DESIGN.read_text())
    found = []
    names = module_names(package)
    for path, name in names.items():
        home = name.split(".")[0]
        if path.parent == package:
            allowed = set(table)  # pipeline/__init__.py only
        elif home not in table:
            found.append(f"{home} is not in the table")
            continue
        else:
            allowed = table[home]
        found += [f"{name} imports {other}" for other in sorted(imports(path, package=package, names=names))
                  if other and other.split(".")[0] not in allowed]
    return sorted(set(found))


def private_names_taken(package: Path = PACKAGE) -> list[str]:
    """Every private name (``_x``, not ``__x__``) that a module takes from another module of the
    package, by ``from m import _x`` or ``m._x``, as 'a.b takes c.d._x'."""
    found = []
    names = module_names(package)
    for path, name in names.items():
        for other, taken in imports(path, package=package, names=names).items():
            found += [f"{name} takes {other}.{t}" for t in sorted(taken)
                      if t.startswith("_") and not (t.startswith("__") and t.endswith("__"))]
    return found


def long_functions(package: Path = PACKAGE) -> list[str]:
    """Every function of the package longer than ``MOST_FUNCTION_LINES`` lines, as 'a.b:f N'."""
    found = []
    for path, name in module_names(package).items():
        for node in ast.walk(_tree(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - min([node.lineno, *(d.lineno for d in node.decorator_list)]) + 1
                if length > MOST_FUNCTION_LINES:
                    found.append(f"{name}:{node.name} {length}")
    return found


MODULES = module_names()


def test_every_import_is_one_the_design_table_allows():
    assert violations() == []


def test_the_table_runs_one_way():
    """The packages stand on floors: no package may import one that may import it back."""
    table = import_table(DESIGN.read_text())
    both = [f"{a} <-> {b}" for a in table for b in table[a] if a < b and a in table.get(b, set())]
    assert both == []


def test_pipeline_holds_subpackages_not_modules():
    """Every module lives in a subpackage; the top holds ``__init__`` alone (docs/design.md, "Packages")."""
    top = sorted(path.name for path in PACKAGE.glob("*.py"))
    assert top == ["__init__.py"]
    packages = sorted(path.parent.name for path in PACKAGE.glob("*/__init__.py"))
    assert set(packages) == set(import_table(DESIGN.read_text())), packages


def test_every_subpackage_says_what_it_holds_and_may_import():
    for init in sorted(PACKAGE.glob("*/__init__.py")):
        doc = ast.get_docstring(ast.parse(init.read_text())) or ""
        assert "May import:" in doc or "Imports nothing" in doc, init


def test_every_module_has_its_row_in_the_modules_table():
    """docs/design.md, "Modules", says what each module of pipeline/ owns."""
    section = DESIGN.read_text().split("## Modules", 1)[1].split("\n## ", 1)[0]
    listed = {name for line in section.splitlines() if line.startswith("| ")
              for name in re.findall(r"`([\w/]+)\.py`", line.split("|")[1])}
    modules = {path.relative_to(PACKAGE).with_suffix("").as_posix() for path in MODULES
               if path.stem not in ("__init__", "__main__")}
    assert modules - listed == set()
    assert listed - modules == set()


def _copy(tmp_path):
    copy = tmp_path / "pipeline"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    return copy


def test_the_table_check_fails_on_a_low_module_importing_a_high_one(tmp_path):
    """A copy of the package where core/geometry.py imports the command line (docs/design.md's
    example) fails, in either spelling of the import."""
    copy = _copy(tmp_path)
    geometry = copy / "core" / "geometry.py"
    geometry.write_text(geometry.read_text() + "\nfrom pipeline.cli import main\n")
    assert violations(copy) == ["core.geometry imports cli.main"]
    geometry.write_text(geometry.read_text() + "\nfrom ..stages.frame import render_frame\n")
    assert violations(copy) == ["core.geometry imports cli.main", "core.geometry imports stages.frame"]


def test_there_is_no_private_name_taken_across_modules():
    assert private_names_taken() == []


def test_the_private_name_check_fails_on_one_taken(tmp_path):
    """A copy where the frame stage takes a private name of the camera, by name and as an attribute."""
    copy = _copy(tmp_path)
    frame = copy / "stages" / "frame.py"
    frame.write_text(frame.read_text() + "\nfrom pipeline.camera.pinhole import _hidden\n"
                     "from pipeline.core import geometry as g\nX = g._secret\n")
    assert private_names_taken(copy) == ["stages.frame takes camera.pinhole._hidden",
                                         "stages.frame takes core.geometry._secret"]


def test_a_resume_with_nothing_to_do_imports_no_numpy():
    """The command, the config and the run folder's checks (docs/design.md): a resume that
    finds every frame done is decided without numpy, a stage or a physics module."""
    code = ("import sys, pipeline.cli.main, pipeline.config.parse, pipeline.stages.resolve, pipeline.run.record; "
            "print(sorted(m for m in sys.modules if m == 'numpy' or m.startswith('pipeline.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=PACKAGE.parent).stdout
    assert "numpy" not in out and "pipeline.stages.plan" not in out, out


def test_there_is_no_import_cycle():
    graph = {name: set(imports(path, top_level_only=True, names=MODULES)) for path, name in MODULES.items()}
    done, trail, cycles = set(), [], []

    def visit(name):
        if name in trail:
            cycles.append(" -> ".join([*trail[trail.index(name):], name]))
            return
        if name in done:
            return
        trail.append(name)
        for other in sorted(graph.get(name, ())):
            visit(other)
        trail.pop()
        done.add(name)

    for name in graph:
        visit(name)
    assert cycles == []


@pytest.mark.parametrize("path", list(MODULES), ids=list(MODULES.values()))
def test_no_module_is_longer_than_the_most(path):
    assert path.read_text().count("\n") <= MOST_LINES


def test_no_function_is_longer_than_the_most():
    assert long_functions() == []


def test_the_function_check_sees_a_long_one(tmp_path):
    copy = _copy(tmp_path)
    body = "".join(f"    x{i} = {i}\n" for i in range(MOST_FUNCTION_LINES))
    (copy / "core" / "long.py").write_text(f"def f():\n{body}")
    assert long_functions(copy) == [f"core.long:f {MOST_FUNCTION_LINES + 1}"]


def test_the_docs_the_code_cites_exist():
    """Every 'docs/NAME.md, "Section"' a comment or docstring cites names a heading there."""
    docs = PACKAGE.parent / "docs"
    cited = set()
    for path in MODULES:
        text = " ".join(path.read_text().split())
        cited |= set(re.findall(r'docs/(\w+\.md), "([^"]+)"', text))
    assert cited
    for name, section in sorted(cited):
        headings = [line.lstrip("#").strip() for line in (docs / name).read_text().splitlines()
                    if line.startswith("#")]
        assert any(h.startswith(section) for h in headings), (name, section)
