"""``dstenv generate --ray`` on a real two-node Ray cluster started with ``ray start``.

The cluster is the README's recipe (docs/throughput.md, "Ray cluster"), run on this
machine: a head node and a second worker node, each its own ``ray start`` with its
own CPUs, custom resource and temp dir, node addresses on the loopback network
(127.0.0.2 head, 127.0.0.3 worker). ``ray`` is invoked as
``python -m ray.scripts.scripts`` and ``dstenv`` as ``python -m dstenv.cli`` (the
same entry points as the console scripts) so that both nodes run this interpreter.

Checked: the shards are byte-identical to a local run; a driver killed with SIGKILL
mid-run leaves only whole shards and a rerun completes the dataset; a worker node
killed with SIGKILL mid-run (its whole process group: raylet, object store, workers)
costs nothing but time (its tasks are retried on the head, or the rerun redoes them).

Needs the ``ray`` extra; marked ``ray`` (not in the default run): ``python -m pytest
-m ray tests/data/test_ray_cluster.py``.
"""

from __future__ import annotations

import hashlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dstenv.cli import main

from .test_end_to_end import TINY_ARGS

pytestmark = pytest.mark.ray
pytest.importorskip("ray")

HEAD_IP, WORKER_IP = "127.0.0.2", "127.0.0.3"
RAY = [sys.executable, "-m", "ray.scripts.scripts"]
DSTENV = [sys.executable, "-m", "dstenv.cli"]
# 12 frames in 6 shards of 2: enough tasks for both nodes and for a kill mid-run. Two
# thousand steps between kept frames make each shard take about a second, so shards
# land about a second apart, and the kill after the first one lands mid-run (with
# TINY_ARGS' 10 steps a shard took milliseconds and a slow driver could write all six
# before the test saw the first: CI failed so once)
SPEC = ["--frames", "12", "--seed", "5", "--split", "train", *TINY_ARGS,
        "--episode-length", "4001", "--stride", "2000"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _digests(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _start_node(args: list[str], log: Path, env: dict[str, str]) -> subprocess.Popen:
    """``ray start ... --block`` in its own session, so its process group is the node."""
    with log.open("w") as fh:
        return subprocess.Popen([*RAY, "start", "--block", *args], stdout=fh,
                                stderr=subprocess.STDOUT, env=env, start_new_session=True)


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=60)


def _alive_nodes(address: str, env: dict[str, str]) -> int:
    code = ("import ray; ray.init(address=%r, logging_level='ERROR', log_to_driver=False); "
            "print(sum(n['Alive'] for n in ray.nodes()))" % address)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120)
    lines = out.stdout.strip().splitlines()
    return int(lines[-1]) if out.returncode == 0 and lines else 0


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A head and a worker node started with ``ray start`` (docs/throughput.md recipe)."""
    tmp = tmp_path_factory.mktemp("ray")
    port = _free_port()
    address = f"{HEAD_IP}:{port}"
    # a ~/.ray/auth_token (written by any earlier ray.init of Ray >= 2.5x) turns token
    # authentication on for `ray start` but not for the clients: the nodes never join
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "disabled"}
    env.pop("RAY_ADDRESS", None)
    common = ["--num-cpus=1", "--object-store-memory=80000000", "--disable-usage-stats",
              "--include-dashboard=false"]
    head = _start_node([
        "--head", f"--node-ip-address={HEAD_IP}", f"--port={port}", *common,
        '--resources={"head_node": 1}', f"--temp-dir={tmp / 'head'}",
        f"--ray-client-server-port={_free_port()}",
        f"--dashboard-agent-listen-port={_free_port()}",
    ], tmp / "head.log", env)
    nodes = {"head": head}
    try:
        worker_args = [
            f"--address={address}", f"--node-ip-address={WORKER_IP}", *common[:3],
            '--resources={"worker_node": 1}', f"--temp-dir={tmp / 'worker'}",
            f"--dashboard-agent-listen-port={_free_port()}",
        ]
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and "worker" not in nodes:
            time.sleep(3)
            if _alive_nodes(address, env) >= 1:
                nodes["worker"] = _start_node(worker_args, tmp / "worker.log", env)
        while time.monotonic() < deadline and _alive_nodes(address, env) < 2:
            time.sleep(3)
        if _alive_nodes(address, env) < 2:
            logs = "".join(p.read_text()[-2000:] for p in tmp.glob("*.log"))
            pytest.fail(f"the two-node Ray cluster did not come up:\n{logs}")
        yield {"address": address, "env": env, "nodes": nodes, "worker_args": worker_args,
               "tmp": tmp}
    finally:
        for proc in nodes.values():
            _kill_group(proc)


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("local") / "out"
    assert main(["generate", "--out", str(out), *SPEC]) == 0
    return _digests(out)


def _generate(cluster, out: Path) -> subprocess.Popen:
    return subprocess.Popen([*DSTENV, "generate", "--out", str(out), "--ray",
                             cluster["address"], *SPEC], env=cluster["env"],
                            start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def _finish(proc: subprocess.Popen) -> str:
    out, _ = proc.communicate(timeout=600)
    assert proc.returncode == 0, out
    return out


def _wait_for_shard(out: Path, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + 300
    while not list(out.glob("train/*.h5")):
        assert proc.poll() is None, proc.communicate()[0]
        assert time.monotonic() < deadline, "no shard written in 300 s"
        time.sleep(0.02)


def test_cluster_run_is_byte_identical_to_a_local_run(cluster, local_run, tmp_path):
    out = tmp_path / "ray"
    _finish(_generate(cluster, out))
    assert _digests(out) == local_run


def test_killed_driver_then_rerun_completes_identically(cluster, local_run, tmp_path):
    out = tmp_path / "ray"
    proc = _generate(cluster, out)
    _wait_for_shard(out, proc)
    _kill_group(proc)  # SIGKILL: no cleanup, no manifest
    done = [p.name for p in out.glob("train/*.h5")]
    assert done and len(done) < 6 and not (out / "manifest.json").exists()
    _finish(_generate(cluster, out))
    assert _digests(out) == local_run


def test_killed_worker_node_costs_only_time(cluster, local_run, tmp_path):
    out = tmp_path / "ray"
    proc = _generate(cluster, out)
    _wait_for_shard(out, proc)
    _kill_group(cluster["nodes"].pop("worker"))  # the worker node dies mid-run
    try:
        out_text, _ = proc.communicate(timeout=600)
        if proc.returncode != 0:  # the driver gave up on a task: rerun resumes
            _finish(_generate(cluster, out))
        assert _digests(out) == local_run, out_text
    finally:  # bring the worker back for any later test
        cluster["nodes"]["worker"] = _start_node(cluster["worker_args"],
                                                 cluster["tmp"] / "worker2.log",
                                                 cluster["env"])
