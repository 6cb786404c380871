"""The code checked by ruff (the rules in pyproject.toml, [tool.ruff]) and by mypy at its default
strictness ([tool.mypy]): every public function of pipeline/ is typed, and the types hold."""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    result = subprocess.run([sys.executable, "-m", "ruff", "check", "pipeline", "tests", "benchmarks"],
                            cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_mypy_finds_nothing(mypy_result):
    """mypy on pipeline/ (started when the session was collected: tests/conftest.py)."""
    returncode, output = mypy_result
    assert returncode == 0, output


def untyped_public_functions(package: Path = ROOT / "pipeline") -> list[str]:
    """Every public function or method of the package (no leading underscore, not nested in a
    function) with a parameter or a return left unannotated, as 'path:line name'."""
    found = []

    def visit(node, path, in_function):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                public = not child.name.startswith("_") or child.name == "__init__"
                if public and not in_function:
                    params = [*child.args.posonlyargs, *child.args.args, *child.args.kwonlyargs]
                    params = [a for a in params if a.arg not in ("self", "cls")]
                    params += [a for a in (child.args.vararg, child.args.kwarg) if a is not None]
                    returns = child.returns is not None or child.name == "__init__"
                    if not returns or any(a.annotation is None for a in params):
                        found.append(f"{path.relative_to(package.parent)}:{child.lineno} {child.name}")
                visit(child, path, True)
            else:
                visit(child, path, in_function)

    for path in sorted(package.rglob("*.py")):
        visit(ast.parse(path.read_text()), path, False)
    return found


def test_every_public_function_is_typed():
    assert untyped_public_functions() == []


def test_the_typing_check_sees_an_untyped_function(tmp_path):
    (tmp_path / "pipeline").mkdir()
    (tmp_path / "pipeline" / "m.py").write_text("def f(a, b: int) -> int:\n    return b\n\n\n"
                                                "def _g(a):\n    return a\n\n\n"
                                                "class C:\n    def h(self) -> int:\n        return 1\n\n"
                                                "    def k(self, x):\n        return x\n")
    assert untyped_public_functions(tmp_path / "pipeline") == ["pipeline/m.py:1 f", "pipeline/m.py:13 k"]
