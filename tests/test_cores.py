"""cores.in_shares: a loop cut into shares run in the threads of cores.loop_threads."""

import threading

import numpy as np
import pytest

from pipeline.core import cores


def _shares_of(count, threads, monkeypatch, smallest=10):
    monkeypatch.setattr(cores, "SMALLEST_SHARE", smallest)
    seen, lock = [], threading.Lock()

    def loop(start, stop):
        with lock:
            seen.append((start, stop, threading.get_ident()))

    if threads is None:
        cores.in_shares(count, loop)
    else:
        with cores.loop_threads(threads):
            cores.in_shares(count, loop)
    return seen


@pytest.mark.parametrize("count", [0, 9, 10, 25, 1000, 1001])
@pytest.mark.parametrize("threads", [None, 1, 2, 3])
def test_every_item_is_in_one_share_and_each_share_is_big_enough(count, threads, monkeypatch):
    seen = _shares_of(count, threads, monkeypatch)
    covered = np.zeros(count, dtype=int)
    for start, stop, _ in seen:
        covered[start:stop] += 1
    assert (covered == 1).all()
    if len(seen) > 1:
        assert min(stop - start for start, stop, _ in seen) >= 10
        assert len(seen) <= (threads or 1) * cores.SHARES_PER_THREAD


def test_shares_run_in_the_threads_asked_for_and_outside_in_the_callers_alone(monkeypatch):
    assert {ident for *_, ident in _shares_of(1000, None, monkeypatch)} == {threading.get_ident()}
    assert {ident for *_, ident in _shares_of(1000, 1, monkeypatch)} == {threading.get_ident()}
    assert len(_shares_of(1000, 3, monkeypatch)) == 3 * cores.SHARES_PER_THREAD
    # outside the with, and in another thread (a context of its own), one thread again
    with cores.loop_threads(3):
        inner = []
        worker = threading.Thread(target=lambda: inner.append(_shares_of(1000, None, monkeypatch)))
        worker.start()
        worker.join()
    assert len(inner[0]) == 1
    assert len(_shares_of(1000, None, monkeypatch)) == 1


def test_a_shares_error_reaches_the_caller(monkeypatch):
    monkeypatch.setattr(cores, "SMALLEST_SHARE", 10)

    def loop(start, stop):
        if start > 0:
            raise ValueError("share failed")

    with cores.loop_threads(2), pytest.raises(ValueError, match="share failed"):
        cores.in_shares(100, loop)
