"""`--engine ray` on a two-node Ray cluster (two raylets on this machine): a conversion killed with SIGKILL part
way and resumed writes the same bytes as `--engine process`. Needs the `ray` extra (`pytest -m ray`); the pure
helpers that pick the cluster and the in-flight window are tested in the default suite."""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from scenariomax.pipeline import ray_init_options, ray_window

# Small scenes keep the run short; enrichment stays on so workers do the real work. 60 scenarios are 6 units of 10.
CONVERT = ["convert", "--num-scenarios", "60", "--num-objects", "16", "--roadgraph-points", "2000",
           "--num-paths", "2", "--points-per-path", "100", "--shard-size", "4"]
NODE_START_S = 60.0
JOB_WORKER_LOG = re.compile(r"^worker-[0-9a-f]+-([0-9a-f]{8})-\d+\.out$")  # Ray's per-worker log, named by job id
IDLE_JOB = "ffffffff"  # workers a raylet starts before any job leases them


# ------------------------------------------------------------------------------------------------
# Pure helpers (default suite).


def test_ray_joins_the_cluster_that_address_or_ray_address_names():
    assert ray_init_options("10.0.0.1:6379", {}, 4) == {"address": "10.0.0.1:6379"}
    assert ray_init_options(None, {"RAY_ADDRESS": "10.0.0.2:6379"}, 4) == {"address": "10.0.0.2:6379"}
    assert ray_init_options("10.0.0.1:6379", {"RAY_ADDRESS": "10.0.0.2:6379"}, 4)["address"] == "10.0.0.1:6379"
    assert ray_init_options(None, {}, 3) == {"num_cpus": 3, "include_dashboard": False}  # a local instance


def test_ray_window_follows_the_cluster_not_the_driver():
    assert ray_window(None, 256.0) == 512  # a 256-CPU cluster driven from a 2-core laptop
    assert ray_window(8, 256.0) == 16  # --workers caps it
    assert ray_window(None, 0.0) == 2  # no CPU reported yet: still makes progress


# ------------------------------------------------------------------------------------------------
# The two-node cluster.


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _wait_for_line(log: Path, text: str, node: subprocess.Popen) -> None:
    deadline = time.monotonic() + NODE_START_S
    while time.monotonic() < deadline and node.poll() is None:
        if log.exists() and text in log.read_text(errors="replace"):
            return
        time.sleep(0.2)
    raise RuntimeError(f"ray node did not start: {log.read_text(errors='replace')[-2000:] if log.exists() else ''}")


def _start_node(ray_bin: Path, root: Path, name: str, role: list[str], env: dict) -> subprocess.Popen:
    """`ray start --block` in its own session, so teardown can signal every process the node spawned."""
    log = root / f"{name}.log"
    args = [str(ray_bin), "start", *role, "--block", "--num-cpus=1", "--node-ip-address=127.0.0.1",
            f"--temp-dir={root / name}", "--object-store-memory=100000000", "--disable-usage-stats"]
    with open(log, "wb") as stream:
        node = subprocess.Popen(args, stdout=stream, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    _wait_for_line(log, "Ray runtime started", node)
    return node


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _stop_node(node: subprocess.Popen, grace_s: float = 5.0) -> None:
    """SIGTERM to the node's session (Ray shuts down cleanly), SIGKILL to whatever outlives the grace period."""
    for sig, wait_s in ((signal.SIGTERM, grace_s), (signal.SIGKILL, 5.0)):
        if not _group_alive(node.pid):
            break
        os.killpg(node.pid, sig)
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and _group_alive(node.pid):
            node.poll()  # reap the `ray start` process itself, else it lingers as a zombie of ours
            time.sleep(0.1)
    node.wait(timeout=5)


@pytest.fixture
def two_node_cluster() -> Iterator[tuple[str, dict, Path]]:
    """(GCS address, environment for Ray processes and drivers, folder holding both nodes' temp dirs)."""
    pytest.importorskip("ray", reason="the ray extra is not installed")
    ray_bin = Path(sys.executable).with_name("ray")
    if not ray_bin.exists():
        pytest.skip("the `ray` command of the ray extra is not next to this Python")
    # Short paths: Ray's Unix sockets live under --temp-dir and pytest's tmp_path would pass their 107-byte limit.
    root = Path(tempfile.mkdtemp(prefix="vmax-ray-", dir="/tmp"))
    token = root / "auth_token"
    token.write_text(secrets.token_hex(32))
    # A private token: the cluster does not depend on (or write) ~/.ray, and Ray versions without auth ignore it.
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN_PATH": str(token)}
    env.pop("RAY_ADDRESS", None)
    address = f"127.0.0.1:{_free_port()}"
    nodes: list[subprocess.Popen] = []
    try:
        nodes.append(_start_node(ray_bin, root, "head", ["--head", f"--port={address.split(':')[1]}",
                                                         "--include-dashboard=false"], env))
        nodes.append(_start_node(ray_bin, root, "node2", [f"--address={address}"], env))
        yield address, env, root
    finally:
        for node in reversed(nodes):
            _stop_node(node)
        assert not [node.pid for node in nodes if _group_alive(node.pid)], "ray processes outlived the test"
        shutil.rmtree(root, ignore_errors=True)


def _cli(args: list[str], env: dict, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vmax_cli.scenariomax_cli", *args], env=env, capture_output=True,
                          text=True, timeout=300, **kwargs)


def _kill_when_a_unit_is_done(args: list[str], env: dict, out: Path) -> dict:
    """Starts a conversion and SIGKILLs it once the manifest says one unit is saved; returns that manifest."""
    driver = subprocess.Popen([sys.executable, "-m", "vmax_cli.scenariomax_cli", *args], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline, manifest = time.monotonic() + 240, {}
    try:
        while time.monotonic() < deadline and driver.poll() is None:
            try:
                manifest = json.loads((out / "manifest.json").read_text())
            except (FileNotFoundError, json.JSONDecodeError):  # not written yet, or caught mid-replace
                manifest = {}
            if manifest.get("counts", {}).get("units_done", 0) >= 1:
                break
            time.sleep(0.02)
    finally:
        driver.send_signal(signal.SIGKILL)
        driver.wait()
    return manifest


def _shard_bytes(out: Path) -> dict[str, bytes]:
    return {path.name: path.read_bytes() for path in sorted(out.glob("*.tfrecord"))}


def _jobs_per_node(root: Path) -> dict[str, set[str]]:
    """Job ids of the workers each raylet started for a job (its session logs): which nodes ran tasks."""
    jobs: dict[str, set[str]] = {}
    for node in ("head", "node2"):
        names = [path.name for path in (root / node).glob("session_*/logs/worker-*.out")]
        jobs[node] = {m.group(1) for m in map(JOB_WORKER_LOG.match, names) if m} - {IDLE_JOB}
    return jobs


@pytest.mark.ray
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_killed_and_resumed_on_two_nodes_matches_the_process_engine(two_node_cluster, tmp_path):
    address, env, root = two_node_cluster
    reference, crashed = tmp_path / "process", tmp_path / "ray"
    done = _cli([*CONVERT, "--workers", "2", "--out", str(reference)], env)
    assert done.returncode == 0, done.stderr[-2000:]

    manifest = _kill_when_a_unit_is_done([*CONVERT, "--engine", "ray", "--address", address, "--out", str(crashed)],
                                         env, crashed)
    counts = manifest.get("counts", {})
    assert manifest.get("state") == "running" and 1 <= counts.get("units_done", 0) < counts.get("units", 0), \
        f"the kill did not land part way: {counts}"
    assert not (crashed / "train-00000-of-00015.tfrecord").exists()

    # Resume through RAY_ADDRESS, the variable `ray job submit` sets, rather than --address.
    resumed = _cli([*CONVERT, "--engine", "ray", "--resume", "--out", str(crashed)], {**env, "RAY_ADDRESS": address})
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert re.search(r"inputs\s+6 \([1-5] already done\)", resumed.stdout), resumed.stdout

    assert _shard_bytes(crashed) == _shard_bytes(reference) and len(_shard_bytes(reference)) == 15
    final = json.loads((crashed / "manifest.json").read_text())
    assert final["state"] == "complete" and final["counts"]["scenarios"] == 60 and not final["failures"]
    assert not (crashed / ".work").exists()
    jobs = _jobs_per_node(root)
    assert all(jobs.values()), f"a raylet ran no conversion task: {jobs}"
