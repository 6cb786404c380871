import os

import pytest

from pipeline.core import paths


@pytest.mark.parametrize("text,words", [
    ("leaves\x00.png", "NUL byte"),
    ("a/" + "x" * (paths.NAME_MAX + 1) + "/b", f"is {paths.NAME_MAX + 1} bytes long"),
    ("/".join(["y" * 200] * 25), "the path is"),
    ("~no-such-user-of-sunshade/cache", "cannot resolve '~no-such-user-of-sunshade'"),
    ("", "is empty"),
    (3, "must be a path"),
])
def test_problem_names_what_is_wrong(text, words):
    found = paths.problem(text)
    assert found is not None and words in found
    assert "\n" not in found


@pytest.mark.parametrize("text", ["leaves.png", "~/cache", "x" * paths.NAME_MAX, "a b/é.png",
                                  os.path.join("..", "renders", "eclipse")])
def test_good_paths_have_no_problem(text):
    assert paths.problem(text) is None


def test_the_longest_name_is_what_the_system_allows(tmp_path):
    os.mkdir(tmp_path / ("x" * paths.NAME_MAX))  # the limit is real: one byte more fails
    with pytest.raises(OSError):
        os.mkdir(tmp_path / ("x" * (paths.NAME_MAX + 1)))
