import pickle
import threading

import pytest

from pipeline.core import errors
from pipeline.core.errors import BadInput, ConfigError, RunError
from pipeline.core.io import ImageError

EXAMPLES = [
    ConfigError("cfg.yaml:3: canopy.height", "must be above 0 (got -1)"),
    ImageError("/data/leaves.png", "cannot read image (truncated)"),
    RunError("--frames: 9 is outside 0..7 (animation.frames is 8)"),
    BadInput("--jobs must be at least 1 (got 0)"),
    errors.WorkerError("KeyError: 'x'", "Traceback (most recent call last):\n  ...\nKeyError: 'x'\n"),
]


@pytest.mark.parametrize("error", EXAMPLES, ids=lambda e: type(e).__name__)
def test_every_error_that_crosses_a_process_boundary_pickles(error):
    copy = pickle.loads(pickle.dumps(error))
    assert type(copy) is type(error)
    assert str(copy) == str(error) and copy.args == error.args
    assert vars(copy) == vars(error)  # path, where, details


def test_the_one_line_errors_are_the_ones_the_cli_reports():
    for error in EXAMPLES[:4]:
        assert isinstance(error, errors.SunshadeError)
    assert ImageError("a.png", "x").path.name == "a.png"
    assert str(ConfigError("f.yaml: sky.alpha", "must be below 90")) == "f.yaml: sky.alpha: must be below 90"


class _TwoArguments(Exception):
    """An exception that does not cross a process boundary: two arguments to its __init__ (the
    trouble ImageError and ConfigError had), and a lock that pickles in no way (tblib, which
    Dask installs, makes the first kind picklable)."""

    def __init__(self, a, b):
        super().__init__(f"{a} and {b}")
        self.lock = threading.Lock()


def _raises_unpicklable():
    raise _TwoArguments("one", "two")


def test_portable_sends_an_unpicklable_failure_back_as_a_worker_error():
    with pytest.raises(TypeError):  # the reference: pickling alone does not round-trip it
        pickle.loads(pickle.dumps(_TwoArguments("one", "two")))
    with pytest.raises(errors.WorkerError) as caught:
        errors.portable(_raises_unpicklable)()
    copy = pickle.loads(pickle.dumps(caught.value))
    assert str(copy) == "_TwoArguments: one and two"
    assert "_raises_unpicklable" in copy.details and "Traceback" in copy.details


def test_portable_passes_picklable_failures_and_results_through():
    with pytest.raises(ConfigError, match=r"sky\.alpha"):
        errors.portable(lambda: (_ for _ in ()).throw(ConfigError("f: sky.alpha", "bad")))()
    with pytest.raises(OSError) as caught:
        errors.portable(open)("/nonexistent/folder/file")
    assert caught.value.filename == "/nonexistent/folder/file"
    assert errors.portable(sum)([1, 2, 3]) == 6
