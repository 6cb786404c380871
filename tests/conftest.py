import subprocess
import sys
from pathlib import Path

import pytest
from scenes import write_inputs

ROOT = Path(__file__).resolve().parents[1]
MYPY_COMMAND = [sys.executable, "-m", "mypy", "--no-incremental", "pipeline"]
"""What tests/test_lint.py's mypy check runs (its default strictness, pyproject.toml [tool.mypy])."""
_mypy: dict[str, subprocess.Popen] = {}


def pytest_collection_finish(session):
    """Start mypy as soon as the session knows it will check types: it takes one core for some
    20 s, which the mostly single-process tests before test_lint leave free."""
    if any(item.name == "test_mypy_finds_nothing" for item in session.items):
        _mypy["process"] = subprocess.Popen(MYPY_COMMAND, cwd=ROOT, stdout=subprocess.PIPE,
                                            stderr=subprocess.STDOUT, text=True)


@pytest.fixture(scope="session")
def mypy_result():
    """(return code, output) of MYPY_COMMAND, started at collection (or now, if it was not)."""
    process = _mypy.pop("process", None) or subprocess.Popen(
        MYPY_COMMAND, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    output, _ = process.communicate()
    return process.returncode, output


@pytest.fixture(autouse=True)
def private_cache(tmp_path_factory, monkeypatch):
    """Every test gets its own cache folder, never the repository's ./cache."""
    monkeypatch.setenv("SUNSHADE_CACHE", str(tmp_path_factory.mktemp("cache")))


@pytest.fixture
def inputs(tmp_path):
    """(folder holding scenes.write_inputs' files, an empty output folder in it)."""
    write_inputs(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    return tmp_path, out
