import pytest


@pytest.fixture(autouse=True)
def private_cache(tmp_path_factory, monkeypatch):
    """Every test gets its own cache folder, never the repository's ./cache."""
    monkeypatch.setenv("SUNSHADE_CACHE", str(tmp_path_factory.mktemp("cache")))
