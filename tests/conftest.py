import pytest
from scenes import write_inputs


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
