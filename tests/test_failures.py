"""Failures during a run (issues 16 and 19): a full disk in a worker process and a lost Dask
cluster end the run with one line and exit code 2, and the run resumes to the same bytes."""

import contextlib
import os
import re
import resource
import signal
import subprocess
import sys
import time

import pytest
from test_run import TINY, assert_same_files, contents, render_here, sunshade, write_config

from pipeline.cli.main import main

SHORT = {**TINY, "animation": {"frames": 3, "fps": 12}}
"""test_run's tiny config, three frames long: the failures come early, the resumes are short."""
FILE_LIMIT = 20_000
"""The largest file a 'full disk' run may write: cache items and frames fail, config reads not. [byte]"""


def full_disk():
    """In the child before exec: files stop growing at FILE_LIMIT (EFBIG, not a signal), as a
    full disk stops them; the worker processes inherit it."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (FILE_LIMIT, FILE_LIMIT))


@contextlib.contextmanager
def full_disk_here():
    """``full_disk`` in this process for the block: only the soft limit is lowered, so that it
    goes back up after."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (FILE_LIMIT, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)


def error_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("sunshade: error:")]


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """A clean run of SHORT, in this process: (config, its filled cache, the bytes every other run
    must give)."""
    folder = tmp_path_factory.mktemp("short")
    config = write_config(folder, SHORT)
    render_here(config, "--jobs", "1", "--output", folder / "run", "--cache", folder / "cache")
    return config, folder / "cache", contents(folder / "run")


def test_a_full_disk_in_a_worker_is_the_one_line_of_one_process(tmp_path, short, capsys):
    """The same line from the command's own process (``--jobs 1``, run here) and from a worker
    process of a real ``sunshade`` process (``--jobs 2``)."""
    config, cache, reference = short

    def args(jobs):
        return ["render", str(config), "--jobs", jobs, "--output", str(tmp_path / f"run{jobs}"), "--cache", str(cache)]

    capsys.readouterr()
    with full_disk_here():  # the cycle products are cached: the frames' writes fail
        code = main(args("1"))
    said = {"1": (code, capsys.readouterr().err)}
    process = sunshade(*args("2"), preexec_fn=full_disk)
    err = process.communicate(timeout=240)[1]
    said["2"] = (process.returncode, err)
    found = {}
    for jobs, (code, err) in said.items():
        folder = tmp_path / f"run{jobs}"
        assert code == 2, err
        assert "Traceback" not in err and "BrokenProcessPool" not in err, err
        lines = error_lines(err)
        assert len(lines) == 1 and err.strip().splitlines()[-1] == lines[0], err
        assert f"{folder}/tiny.0" in lines[0] and "cannot write" in lines[0], lines
        found[jobs] = re.sub(r"\d+", "N", lines[0].replace(str(folder), "RUN"))
    assert found["1"] == found["2"]  # the same line, whatever the process it came from
    render_here(config, "--jobs", "1", "--output", tmp_path / "run2", "--cache", cache)
    assert_same_files(tmp_path / "run2", reference)  # space back: it resumes


def dask_worker(address):
    """A real Dask worker process of two threads (with one, joblib would run the tasks here),
    and no nanny to bring it back when it is killed."""
    return subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                             "--no-nanny", "--nthreads", "2", "--no-dashboard"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def test_losing_every_worker_ends_the_run_in_the_stated_time_and_it_resumes(tmp_path, short):
    distributed = pytest.importorskip("distributed")
    config, _, reference = short
    with distributed.LocalCluster(n_workers=0, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        worker = dask_worker(cluster.scheduler_address)
        try:
            client.wait_for_workers(1, timeout=60)
            process = sunshade("render", config, "--scheduler", cluster.scheduler_address,
                               "--cluster-timeout", "1", "--output", tmp_path / "run",
                               "--cache", tmp_path / "cache")
            seen = []
            for line in process.stderr:  # the cycle products are being made on the worker
                seen.append(line)
                if "cycle products 0/" in line:
                    break
            worker.kill()
            _, err = process.communicate(timeout=120)
        finally:
            worker.kill()
            worker.wait()
        err = "".join(seen) + err
        assert process.returncode == 2, err
        assert error_lines(err) == [err.strip().splitlines()[-1]], err
        assert "lost the cluster (no workers for 1 s)" in err and "run the same command again" in err
        assert "Traceback" not in err
        assert not (tmp_path / "run").exists() or contents(tmp_path / "run") != reference
        worker = dask_worker(cluster.scheduler_address)
        try:
            client.wait_for_workers(1, timeout=60)  # the resume: its frames rendered on the new worker
            render_here(config, "--scheduler", cluster.scheduler_address,
                        "--output", tmp_path / "run", "--cache", tmp_path / "cache")
        finally:
            worker.kill()
            worker.wait()
    assert_same_files(tmp_path / "run", reference)


def test_losing_the_scheduler_ends_the_run_with_one_line(tmp_path):
    distributed = pytest.importorskip("distributed")
    config = write_config(tmp_path)
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=True,
                                       host="127.0.0.1", dashboard_address=None)
    process = sunshade("render", config, "--scheduler", cluster.scheduler_address,
                       "--cluster-timeout", "1", "--output", tmp_path / "run",
                       "--cache", tmp_path / "cache")
    seen = []
    for line in process.stderr:
        seen.append(line)
        if "cycle products 0/" in line:
            break
    cluster.close()
    _, err = process.communicate(timeout=120)
    err = "".join(seen) + err
    assert process.returncode == 2, err
    assert error_lines(err) == [err.strip().splitlines()[-1]], err
    assert "lost the cluster" in err and "Traceback" not in err


def loky_workers(pid):
    """The joblib (loky) worker processes among the children of process ``pid`` (Linux /proc)."""
    found = []
    for task in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{task}/children") as children:
            for child in children.read().split():
                with contextlib.suppress(OSError), open(f"/proc/{child}/cmdline") as cmdline:
                    if "popen_loky" in cmdline.read():
                        found.append(int(child))
    return found


@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="finds the workers in /proc")
def test_a_worker_process_killed_ends_the_run_with_one_line(tmp_path):
    config = write_config(tmp_path, SHORT)
    process = sunshade("render", config, "--jobs", "2", "--output", tmp_path / "run",
                       "--cache", tmp_path / "cache")
    deadline = time.monotonic() + 120
    while not (workers := loky_workers(process.pid)) and time.monotonic() < deadline:
        time.sleep(0.01)  # the cycle phase starts its two workers
    os.kill(workers[0], signal.SIGKILL)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 2, err
    assert error_lines(err) == ["sunshade: error: a worker process died (killed, or out of memory?); "
                                "done frames are kept: run the same command again to resume"], err
    assert "Traceback" not in err


def test_a_cluster_without_workers_ends_the_run_and_writes_nothing(tmp_path, short, capfd):
    """The command in this process (what it says is what a process of its own says: the one
    line, from the same code, as test_losing_the_scheduler_ends_the_run_with_one_line's)."""
    distributed = pytest.importorskip("distributed")
    config, _, _ = short
    with distributed.LocalCluster(n_workers=0, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        capfd.readouterr()
        code = main(["render", str(config), "--scheduler", cluster.scheduler_address,
                     "--cluster-timeout", "1", "--output", str(tmp_path / "new" / "run"),
                     "--cache", str(tmp_path / "cache")])
        err = capfd.readouterr().err
    assert code == 2, err
    assert error_lines(err) == [err.strip().splitlines()[-1]], err
    assert "lost the cluster (no workers for 1 s)" in err and "Traceback" not in err
    assert not (tmp_path / "new").exists()


def state(pid: int) -> tuple[str, int] | None:
    """(state letter, parent PID) of a process from /proc, or None once it is gone."""
    with contextlib.suppress(OSError):
        letter, parent = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[:2]
        return letter, int(parent)
    return None


def children(pid: int) -> list[int]:
    """The live processes whose parent is ``pid``."""
    return [int(name) for name in os.listdir("/proc") if name.isdigit()
            and (found := state(int(name))) is not None and found[1] == pid and found[0] != "Z"]


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="reads /proc")
def test_the_workers_of_a_killed_render_end_with_it(tmp_path):
    """SIGKILL to the command while its two worker processes render: within a few seconds no
    process it started is left (before, the workers rendered on and then idled for minutes)."""
    config = write_config(tmp_path, {**TINY, "animation": {"frames": 400, "fps": 12}})
    process = sunshade("render", config, "--jobs", "2", "--output", tmp_path / "run", "--cache", tmp_path / "cache")
    started = time.monotonic()
    while not list((tmp_path / "run").glob("*.0000.png")) and time.monotonic() - started < 120:
        time.sleep(0.05)
    workers = children(process.pid)
    assert len(workers) >= 2, workers
    process.kill()
    process.wait(timeout=30)  # not communicate(): a worker left alive would hold the pipes open
    process.stdout.close()
    process.stderr.close()
    deadline = time.monotonic() + 10.0
    while (left := [pid for pid in workers if (state(pid) or ("Z",))[0] != "Z"]) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert left == []
    assert len(list((tmp_path / "run").glob("*.png"))) < 400
