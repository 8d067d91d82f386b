"""A simulated two-node Ray cluster (``ray.cluster_utils.Cluster``, one CPU per node): a sweep on
it reproduces the serial table, a worker killed mid-sweep is retried by Ray and the table is
complete, and bad addresses or a node lacking the project get one clear error."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import pytest

ray = pytest.importorskip("ray")
pytestmark = pytest.mark.slow  # Ray: make test-all

SWEEP = (
    "task: chain-v1\nenv: {max_cycles: 400}\ngrid:\n  n_modules: [12, 16]\n  motion_model: [minimal, sphere]\n"
    "seeds: 2\nplot: {x: n_modules, hue: motion_model}\n"
)
LONG_SWEEP = "task: chain-v1\nenv: {max_cycles: 4000, motion_model: rhombic}\ngrid:\n  n_modules: [60, 80]\nseeds: 8\n"
"""Batches of worlds that run for seconds (half the chains never form under ``rhombic`` and run to
the cycle limit), so that a Ray task can be killed while it runs: the sweep runs each grid point's
episodes as one batch, one Ray task."""


def test_bad_address_is_one_clear_error(capsys):
    from training.cli import main
    from training.machinery.distributed import ClusterError, connect

    assert not ray.is_initialized()
    with pytest.raises(ClusterError, match=r"--address 'headnode' is not allowed; allowed: HOST:PORT"):
        connect(address="headnode")
    started = time.perf_counter()
    with pytest.raises(ClusterError, match=r"--address '127.0.0.1:9': no Ray head node answers there"):
        connect(address="127.0.0.1:9")
    assert time.perf_counter() - started < 10 and not ray.is_initialized()
    assert main(["eval", "--tasks", "chain", "--address", "127.0.0.1:6379"]) == 2
    assert "--address '127.0.0.1:6379' needs --ray" in capsys.readouterr().err


@pytest.fixture(scope="module")
def two_nodes():
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    cluster.add_node(num_cpus=1)
    ray.init(address=cluster.address, log_to_driver=False)
    yield cluster
    ray.shutdown()
    cluster.shutdown()


def _sweep(tmp_path, name: str, *flags, text: str = SWEEP) -> dict:
    from training.cli import main

    config = tmp_path / "sweep.yaml"
    config.write_text(text)
    assert main(["sweep", str(config), "--out", str(tmp_path / name), *flags]) == 0
    return {f: (tmp_path / name / f).read_text() for f in ("episodes.csv", "summary.csv")}


def test_sweep_on_two_nodes_reproduces_the_serial_table(tmp_path, two_nodes):
    assert len([n for n in ray.nodes() if n["Alive"]]) == 2
    assert _sweep(tmp_path, "ray", "--ray") == _sweep(tmp_path, "serial")


def _running_task_pids() -> list[int]:
    """Worker processes running one of our episodes now (Ray names them after the task)."""
    pids = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and (entry / "cmdline").read_bytes().startswith(b"ray::_attempt"):
                pids.append(int(entry.name))
        except OSError:
            continue
    return pids


def test_worker_killed_mid_sweep_is_retried_and_the_table_is_complete(tmp_path, two_nodes, capfd):
    serial = _sweep(tmp_path, "serial", text=LONG_SWEEP)

    def kill_one(killed, finished):  # a worker that has been running episodes for 0.3 s (its attempt is in the ledger)
        seen = {}
        while not finished.is_set() and not killed:
            now, pids = time.time(), _running_task_pids()
            seen = {pid: seen.get(pid, now) for pid in pids}
            for pid, since in seen.items():
                if now - since > 0.3:
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
                    break
            time.sleep(0.02)

    # The killer sees a worker's process title, not its task: a kill that lands just after a
    # task returned (between two tasks, or at the sweep's end) retries nothing. Every attempt
    # must still give the whole table; at least one of three must have retried a task.
    retried = False
    for attempt in range(3):
        capfd.readouterr()
        killed, finished = [], threading.Event()
        killer = threading.Thread(target=kill_one, args=(killed, finished))
        killer.start()
        try:
            on_ray = _sweep(tmp_path, f"ray{attempt}", "--ray", text=LONG_SWEEP)
        finally:
            finished.set()
            killer.join()
        assert killed, "no running task was found to kill"
        assert on_ray == serial
        if "task(s) retried after their worker died" in capfd.readouterr().err:
            retried = True
            break
    assert retried, "three workers were killed mid-sweep and no task was retried"


def test_node_lacking_the_project_is_named(two_nodes):
    from training.machinery.distributed import PROJECT_MODULES, ClusterError, check_cluster

    assert len(check_cluster()) == 2
    with pytest.raises(
        ClusterError,
        match=r"node .*: cannot import proteo_extension_not_installed .*allowed: every "
        r"node with this checkout installed",
    ):
        check_cluster((*PROJECT_MODULES, "proteo_extension_not_installed"))
