"""Workers die with `dstenv generate`, whatever kills it, and stop writing."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux /proc")


def _start(out: Path) -> subprocess.Popen:
    # far more work than the seconds before the kill: 4000 frames took ~5 s in all on the
    # 2-core machine once the traffic step got faster, so a SIGTERM sent 3 s after the
    # workers started could meet a run already past its cleanup (exit -15, not 143)
    cmd = [sys.executable, "-m", "dstenv.cli", "generate", "--frames", "40000", "--grid", "32",
           "--episode-length", "400", "--stride", "1", "--frames-per-shard", "1000",
           "--workers", "2", "--quiet", "--out", str(out)]
    return subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _group(pgid: int) -> list[int]:
    """Live (non-zombie) processes of a process group."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if int(fields[2]) == pgid and fields[0] != "Z":
            pids.append(int(d.name))
    return pids


def _wait_for_workers(proc: subprocess.Popen, n: int = 3, timeout: float = 120.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if len(_group(proc.pid)) >= n:  # parent, resource tracker / workers
            time.sleep(3.0)  # let the workers import and start simulating
            return
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(0.2)
    pytest.fail("workers did not start")


def _wait_gone(pgid: int, timeout: float = 60.0) -> list[int]:
    end = time.monotonic() + timeout
    while time.monotonic() < end and _group(pgid):
        time.sleep(0.1)
    return _group(pgid)


def _files(out: Path) -> set[tuple[str, int]]:
    return {(str(p), p.stat().st_size) for p in out.rglob("*") if p.is_file()}


def test_sigkill_of_the_parent_kills_the_workers(tmp_path):
    proc = _start(tmp_path / "d")
    _wait_for_workers(proc)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    left = _wait_gone(proc.pid)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert not left, f"workers outlived their parent: {left}"
    before = _files(tmp_path / "d")
    time.sleep(1.0)
    assert _files(tmp_path / "d") == before  # nothing writes after the parent died


def test_sigterm_cleans_up_and_exits_143(tmp_path):
    proc = _start(tmp_path / "d")
    _wait_for_workers(proc)
    os.kill(proc.pid, signal.SIGTERM)
    proc.wait(timeout=60)
    assert proc.returncode == 143, proc.stderr.read()
    assert not _wait_gone(proc.pid)
    assert not list((tmp_path / "d").rglob("*.partial"))  # unfinished shards removed
    assert "rerun the same command" in proc.stderr.read()


def test_a_second_writer_is_refused_while_the_first_runs(tmp_path):
    from dstenv.data.lock import LOCK_NAME, DatasetLocked, dataset_lock

    with dataset_lock(tmp_path / "d") as lock:
        assert lock.name == LOCK_NAME
        with pytest.raises(DatasetLocked, match=r"being written by pid \d+ on .*--force-unlock"):
            with dataset_lock(tmp_path / "d"):
                pass
        # --force-unlock is for a lock whose process is gone, not for a live writer here
        with pytest.raises(DatasetLocked, match=r"still running; --force-unlock is for a lock"):
            with dataset_lock(tmp_path / "d", force=True):
                pass
    assert not (tmp_path / "d" / LOCK_NAME).exists()  # released


def test_a_stale_lock_of_a_dead_process_is_taken_over(tmp_path):
    import json
    import socket

    from dstenv.data.lock import LOCK_NAME, dataset_lock

    d = tmp_path / "d"
    d.mkdir()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    (d / LOCK_NAME).write_text(json.dumps({"host": socket.gethostname(), "pid": int(dead)}))
    with dataset_lock(d):
        pass
    (d / LOCK_NAME).write_text(json.dumps({"host": "other-host", "pid": 1}))
    with dataset_lock(d, force=True):
        pass


def test_an_unowned_lock_blocks_only_while_young_and_a_failed_start_leaves_none(tmp_path,
                                                                               monkeypatch):
    import os
    import time

    import pytest

    from dstenv.data import lock as lock_mod
    from dstenv.data.lock import LOCK_NAME, DatasetLocked, dataset_lock, writer_of

    d = tmp_path / "d"
    d.mkdir()
    (d / LOCK_NAME).write_bytes(b"")  # created, owner never written (e.g. a full disk)
    assert writer_of(d) == "a run that is starting"
    with pytest.raises(DatasetLocked, match="a run that is starting"):
        with dataset_lock(d):
            pass
    old = time.time() - 2 * lock_mod._UNOWNED_STALE_S
    os.utime(d / LOCK_NAME, (old, old))
    assert writer_of(d) is None
    with dataset_lock(d):  # taken over
        pass
    # the owner cannot be written: no lock is left behind
    real_write = os.write

    def full(fd, data):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(lock_mod.os, "write", full)
    with pytest.raises(OSError, match="No space left"):
        with dataset_lock(d):
            pass
    monkeypatch.setattr(lock_mod.os, "write", real_write)
    assert not (d / LOCK_NAME).exists()


def test_a_killed_owner_not_yet_reaped_does_not_hold_the_lock(tmp_path):
    import socket

    from dstenv.data.lock import LOCK_NAME, _started, dataset_lock, writer_of

    d = tmp_path / "d"
    d.mkdir()
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        started = _started(child.pid)
        (d / LOCK_NAME).write_text(json.dumps({"host": socket.gethostname(), "pid": child.pid,
                                               "started": started}))
        assert writer_of(d) is not None  # running: it holds the lock
        os.kill(child.pid, signal.SIGKILL)
        for _ in range(200):  # a zombie until we wait for it (as under a parent that never does)
            if Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                break
            time.sleep(0.01)
        assert writer_of(d) is None
        with dataset_lock(d):
            pass
    finally:
        child.kill()
        child.wait()


def test_a_pid_reused_by_another_process_does_not_hold_the_lock(tmp_path):
    import os
    import socket

    from dstenv.data.lock import LOCK_NAME, dataset_lock, writer_of

    d = tmp_path / "d"
    d.mkdir()
    # our own live pid, but a start time that is not this process's: a reused pid
    (d / LOCK_NAME).write_text(json.dumps({"host": socket.gethostname(), "pid": os.getpid(),
                                           "started": "-1"}))
    assert writer_of(d) is None
    with dataset_lock(d):
        pass


def test_several_processes_taking_a_stale_lock_at_once_get_it_one_at_a_time(tmp_path):
    import multiprocessing as mp
    import socket

    from dstenv.data.lock import LOCK_NAME

    d = tmp_path / "d"
    d.mkdir()
    ctx = mp.get_context("fork")
    for _ in range(5):
        (d / LOCK_NAME).write_text(json.dumps({"host": socket.gethostname(), "pid": 2**22 + 7}))
        held = ctx.Value("i", 0)
        most = ctx.Value("i", 0)
        start = ctx.Event()
        procs = [ctx.Process(target=_hold_briefly, args=(d, held, most, start)) for _ in range(4)]
        for p in procs:
            p.start()
        start.set()
        for p in procs:
            p.join(20)
        assert most.value == 1  # never two holders at once


def _hold_briefly(d, held, most, start) -> None:
    import time

    from dstenv.data.lock import DatasetLocked, dataset_lock

    start.wait()
    try:
        with dataset_lock(d):
            with held.get_lock():
                held.value += 1
                most.value = max(most.value, held.value)
            time.sleep(0.05)
            with held.get_lock():
                held.value -= 1
    except DatasetLocked:
        pass


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")  # the point
def test_a_sigterm_python_swallows_is_raised_on_leaving_the_block():
    import weakref

    from dstenv.data.lifeline import Terminated, sigterm_as_interrupt

    class Obj:
        pass

    with pytest.raises(Terminated, match="signal 15"):
        with sigterm_as_interrupt():
            o = Obj()
            # the signal lands in a weakref callback: Python prints it and goes on
            weakref.finalize(o, lambda: os.kill(os.getpid(), signal.SIGTERM) or time.sleep(0.05))
            del o
            done = True
    assert done


def test_a_lock_released_while_read_is_no_stale_lock_to_take_over(tmp_path, monkeypatch):
    """CI caught two holders at once: B failed to create the lock (A held it), A released
    it before B read it, so B judged the missing lock stale; in its takeover C had just
    created a new lock, still empty, and B removed it (empty == empty) and took its own."""
    import os as _os

    import dstenv.data.lock as lock

    d = tmp_path / "d"
    d.mkdir()
    path = d / lock.LOCK_NAME
    path.write_text("")  # A's lock
    real, calls, c_holds = lock._owner, [], []

    def racing_owner(p):
        calls.append(p)
        if len(calls) == 1:  # A releases just before B reads
            p.unlink()
            return {}
        if len(calls) == 2 and not p.exists():  # C creates its lock, not yet written
            _os.close(_os.open(p, _os.O_CREAT | _os.O_EXCL | _os.O_WRONLY))
            c_holds.append(True)
        return real(p)

    monkeypatch.setattr(lock, "_owner", racing_owner)
    try:
        with lock.dataset_lock(d):
            b_holds = True
    except lock.DatasetLocked:
        b_holds = False
    assert not (b_holds and c_holds), "B took the lock C holds"
    assert not c_holds or path.exists()  # C's lock is still there


def test_sigterm_of_any_command_cleans_up_like_ctrl_c(tmp_path):
    """Attack 17: only generate handled SIGTERM; train (and kitti convert, benchmark) died
    at once (exit -15, no message) and left their folder's lock behind."""
    from dstenv.cli import main
    from dstenv.data.lock import LOCK_NAME

    data = tmp_path / "d"
    assert main(["generate", "--frames", "12", "--grid", "32", "--episode-length", "30",
                 "--frames-per-shard", "4", "--quiet", "--out", str(data)]) == 0
    out = tmp_path / "t"
    proc = subprocess.Popen([sys.executable, "-m", "dstenv.cli", "train", "--data", str(data),
                             "--out", str(out), "--epochs", "100000", "--batch-size", "2",
                             "--num-workers", "0", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not (out / LOCK_NAME).exists() and proc.poll() is None:
        assert time.monotonic() < deadline, "train never took its folder's lock"
        time.sleep(0.1)
    time.sleep(1.0)
    os.kill(proc.pid, signal.SIGTERM)
    proc.wait(timeout=60)
    err = proc.stderr.read()
    assert proc.returncode == 143, err
    assert "dstenv: terminated; finished work is kept" in err
    assert not (out / LOCK_NAME).exists()  # released, as after Ctrl-C
