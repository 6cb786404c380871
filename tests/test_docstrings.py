"""The public names of pipeline/ documented in numpydoc form, checked on the source (ast, no import):
every function and class a module lists in ``__all__`` has a docstring, with a ``Parameters`` section when it
takes parameters (``Attributes`` for a dataclass's fields) and a ``Returns`` (or ``Yields``) section when it
returns a value."""

import ast
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "pipeline"

MODULES_WITH_ALL = sorted(path.relative_to(PACKAGE).with_suffix("").as_posix() for path in PACKAGE.rglob("*.py")
                          if path.stem not in ("__init__", "__main__"))
"""Every module of pipeline/ and its subpackages (as ``sky/eclipse``) names its public names."""

SELF = {"self", "cls"}


def tree_of(name: str) -> ast.Module:
    return ast.parse((PACKAGE / f"{name}.py").read_text(encoding="utf-8"))


def all_names(tree: ast.Module) -> list[str] | None:
    """The names in the module's ``__all__``, or None when it has none."""
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
            node, ast.AnnAssign) else []
        if any(isinstance(target, ast.Name) and target.id == "__all__" for target in targets):
            return [ast.literal_eval(element) for element in node.value.elts]
    return None


def has_section(docstring: str, *titles: str) -> bool:
    """Whether the docstring has a numpydoc section headed by one of the titles (the title on its own line,
    a line of dashes under it)."""
    return any(re.search(rf"^\s*{title}\s*\n\s*-{{3,}}\s*$", docstring, re.MULTILINE) for title in titles)


def parameters(function: ast.FunctionDef | ast.AsyncFunctionDef) -> list[str]:
    arguments = function.args
    named = [a.arg for a in arguments.posonlyargs + arguments.args + arguments.kwonlyargs]
    named += [a.arg for a in (arguments.vararg, arguments.kwarg) if a is not None]
    return [name for name in named if name not in SELF]


def own_nodes(function: ast.FunctionDef | ast.AsyncFunctionDef):
    """The nodes of the function's own body, not those of the functions, lambdas and classes nested in it."""
    stack = list(function.body)
    while stack:
        node = stack.pop()
        yield node
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            stack.extend(ast.iter_child_nodes(node))


def returns_value(function: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    annotation = function.returns
    if annotation is not None and not (isinstance(annotation, ast.Constant) and annotation.value is None):
        return True
    return any(isinstance(node, ast.Return) and node.value is not None
               and not (isinstance(node.value, ast.Constant) and node.value.value is None)
               for node in own_nodes(function))


def is_dataclass(cls: ast.ClassDef) -> bool:
    return any("dataclass" in ast.unparse(decorator) for decorator in cls.decorator_list)


def problems_of_function(function: ast.FunctionDef | ast.AsyncFunctionDef) -> list[str]:
    docstring = ast.get_docstring(function)
    if not docstring:
        return ["no docstring"]
    problems = []
    if parameters(function) and not has_section(docstring, "Parameters"):
        problems.append(f"takes {', '.join(parameters(function))} but has no Parameters section")
    if returns_value(function) and not has_section(docstring, "Returns", "Yields"):
        problems.append("returns a value but has no Returns section")
    return problems


def problems_of_class(cls: ast.ClassDef) -> list[str]:
    docstring = ast.get_docstring(cls)
    if not docstring:
        return ["no docstring"]
    if is_dataclass(cls):
        fields = [node for node in cls.body if isinstance(node, ast.AnnAssign) and "ClassVar" not in ast.unparse(
            node.annotation)]
        if fields and not has_section(docstring, "Parameters", "Attributes"):
            return ["is a dataclass with fields but has no Attributes (or Parameters) section"]
        return []
    init = next((node for node in cls.body if isinstance(node, ast.FunctionDef) and node.name == "__init__"), None)
    if init is not None and parameters(init) and not (has_section(docstring, "Parameters")
                                                     or has_section(ast.get_docstring(init) or "", "Parameters")):
        return [f"takes {', '.join(parameters(init))} but has no Parameters section"]
    return []


def problems(name: str) -> list[str]:
    """What the module's public functions and classes lack, one line each naming module and function."""
    tree = tree_of(name)
    public = set(all_names(tree) or [])
    found = []
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name in public:
            found += [f"pipeline/{name}.py: {node.name}() {problem}" for problem in problems_of_function(node)]
        elif isinstance(node, ast.ClassDef) and node.name in public:
            found += [f"pipeline/{name}.py: class {node.name} {problem}" for problem in problems_of_class(node)]
    return found


MODULES = MODULES_WITH_ALL
DOCUMENTED = [name for name in MODULES if all_names(tree_of(name)) is not None]


@pytest.mark.parametrize("name", DOCUMENTED)
def test_public_functions_and_classes_have_numpydoc_docstrings(name):
    found = problems(name)
    assert not found, "\n".join(found)


@pytest.mark.parametrize("name", MODULES_WITH_ALL)
def test_module_defines_all(name):
    public = all_names(tree_of(name))
    assert public is not None, f"pipeline/{name}.py has no __all__"
    defined = set()
    for node in tree_of(name).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            defined.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            defined.update(target.id for target in targets if isinstance(target, ast.Name))
    assert not set(public) - defined, f"pipeline/{name}.py: __all__ names what it does not define: " \
                                      f"{sorted(set(public) - defined)}"
    assert len(public) == len(set(public)), f"pipeline/{name}.py: __all__ names a name twice"


def test_the_check_sees_a_missing_section():
    tree = ast.parse('def f(a):\n    """Summary."""\n    return a\n')
    assert problems_of_function(tree.body[0]) == ["takes a but has no Parameters section",
                                                  "returns a value but has no Returns section"]
