"""Many independent episodes, run in this process or as Ray tasks, journaled as they finish.

``proteo eval``, :mod:`training.trainers.cma_es` and ``proteo sweep`` all reduce their work to a list of
*jobs* (small picklable descriptions of one episode) and a module-level function that runs
one job and returns a small picklable result. :func:`run_jobs` runs them:

- serially in this process (the default),
- on a pool of local worker processes (``workers``), or
- as Ray tasks (``--ray``), each asking for one CPU, on a local Ray instance with
  ``--workers`` CPUs or on a running cluster (``--address``). Ray is imported only then.

Either way the result of each job depends only on the job (every job carries its seed), so a
run on Ray gives exactly the serial results, whatever the order in which tasks finish.

A :class:`Journal` (one JSON line per finished job, flushed as it arrives) lets an
interrupted run resume: rerunning the same command skips the jobs already in the journal, and
a journal is never counted twice (a job's key is written once; a torn last line from a crash
is ignored). A worker process that dies mid-task is retried by Ray itself (``max_retries``);
every task records its attempts with a small ledger actor, and the run reports the retries.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import multiprocessing
import os
import socket
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from proteo_env.config import ConfigError

PROJECT_MODULES = ("proteo_env", "baselines", "training")
"""The packages every Ray worker must import (the project, installed on each node)."""

DEFAULT_MAX_RETRIES = 3
"""Ray retries of a task whose worker process died (application errors are not retried)."""


class ClusterError(ConfigError):
    """Ray cannot be used as asked (no Ray installed, unreachable address, a node without the project)."""


# ---------------------------------------------------------------------- settings
def ray_options(args) -> dict | None:
    """``{"address", "workers"}`` from parsed ``--ray/--address/--workers`` flags, or ``None`` (serial).

    ``--address`` without ``--ray`` is an error, so that a cluster run never silently runs
    locally; ``--workers`` without ``--ray`` is the number of local worker processes (where the
    command runs its episodes in batches, :mod:`training.machinery.evaluator`).
    """
    use = bool(getattr(args, "ray", False))
    address, workers = getattr(args, "address", None), getattr(args, "workers", None)
    if not use and address is not None:
        raise ConfigError(
            f"--address {address!r} needs --ray; allowed: --ray --address ... (or neither, to run on this machine)"
        )
    if workers is not None and int(workers) < 1:
        raise ConfigError(f"--workers {workers!r} is not allowed; allowed: an integer >= 1")
    return {"address": address, "workers": None if workers is None else int(workers)} if use else None


def add_ray_flags(parser) -> None:
    """Add ``--ray``, ``--address`` and ``--workers`` to an argparse parser."""
    g = parser.add_argument_group("Ray (pip install -e '.[distributed]')")
    g.add_argument("--ray", action="store_true", help="run the episodes as Ray tasks")
    g.add_argument(
        "--address",
        default=None,
        help="a running Ray cluster (HOST:PORT printed by `ray start "
        "--head`, or 'auto'); default: start a local Ray instance",
    )
    g.add_argument(
        "--workers",
        type=int,
        default=None,
        help="worker processes on this machine (default: all cores); with --ray, CPUs of the local Ray "
        "instance, or at most this many tasks at once on a cluster",
    )


# ---------------------------------------------------------------------- journal
class Journal:
    """Finished jobs of one run, one JSON line each: ``{"key": str, "result": ...}``.

    The first line holds the run's ``fingerprint`` (everything its results depend on); the
    last line of a finished run is ``{"complete": true}``. Opening a journal of an unfinished
    run with the same fingerprint resumes it (:attr:`done` holds its results); a different
    fingerprint is an error unless ``fresh``; a finished run's journal is started anew.
    """

    def __init__(self, path, fingerprint: dict, *, fresh: bool = False, what: str = "run"):
        self.path = Path(path)
        fingerprint = json.loads(json.dumps(fingerprint, default=str))  # as it reads back (tuples: lists)
        self.done: dict[str, object] = {}
        self.resumed = False
        if self.path.is_file() and not fresh:
            lines = self.path.read_text().splitlines()
            records = []
            for line in lines:
                try:
                    records.append(json.loads(line))
                except json.JSONDecodeError:  # a line torn by the interruption
                    break
            complete = any(r.get("complete") for r in records)
            if records and not complete:
                if records[0].get("fingerprint") != fingerprint:
                    old = records[0].get("fingerprint") or {}
                    diff = sorted(k for k in set(old) | set(fingerprint) if old.get(k) != fingerprint.get(k))
                    raise ConfigError(
                        f"{str(self.path)!r} holds an unfinished {what} with other settings "
                        f"(differing: {', '.join(diff) or 'format'}); allowed: the same settings to "
                        "resume it, another output folder, or --fresh to discard it"
                    )
                for r in records[1:]:
                    if "key" in r:
                        self.done.setdefault(r["key"], r["result"])
                self.resumed = True
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if not self.resumed:
            self.path.write_text(json.dumps({"fingerprint": fingerprint}) + "\n")
        else:  # drop a torn last line so appended records start on a line of their own
            self.path.write_text(
                "".join(
                    json.dumps(r) + "\n"
                    for r in [{"fingerprint": fingerprint}] + [{"key": k, "result": v} for k, v in self.done.items()]
                )
            )

    def add(self, key: str, result) -> None:
        """Record one finished job (ignored when its key is already recorded)."""
        self.add_many([(key, result)])

    def add_many(self, records) -> None:
        """Record finished jobs ``(key, result)`` with one write to disk (those already recorded are ignored)."""
        lines = []
        for key, result in records:
            if key not in self.done:
                self.done[key] = result
                lines.append(json.dumps({"key": key, "result": result}, default=float) + "\n")
        if lines:
            with self.path.open("a") as fh:
                fh.write("".join(lines))
                fh.flush()
                os.fsync(fh.fileno())

    def complete(self) -> None:
        """Mark the run finished: the next run with this journal starts anew."""
        with self.path.open("a") as fh:
            fh.write(json.dumps({"complete": True}) + "\n")


# ---------------------------------------------------------------------- running jobs
def run_jobs(
    fn: Callable,
    jobs: Sequence,
    keys: Sequence[str],
    *,
    ray: dict | None = None,
    workers: int | None = None,
    journal: Journal | None = None,
    desc: str = "episodes",
    progress: bool = True,
    max_retries: int = DEFAULT_MAX_RETRIES,
    sizes: Sequence[int] | None = None,
    on_result: Callable[[int, object], None] | None = None,
) -> list:
    """``[fn(job) for job in jobs]``, serially, on local worker processes or as Ray tasks; results in job order.

    Args:
        fn: a module-level function ``fn(job) -> result`` (picklable by reference; the result
            must be JSON-serialisable when a journal is used).
        jobs: the jobs, ``len(jobs) == len(keys)``.
        keys: a unique, stable name per job (the journal's key).
        ray: ``None`` (serial) or ``{"address", "workers"}`` (see :func:`ray_options`).
        workers: without ``ray``, run the jobs on this many local processes (:func:`local_pool`;
            ``None`` or 1: in this process).
        journal: finished jobs are skipped and new ones recorded in it as they arrive.
        progress: a tqdm bar counting finished jobs.
        max_retries: Ray retries of a task whose worker died.
        sizes: what each job counts for on the progress bar (default 1 each; a batch of
            episodes counts its episodes).
        on_result: called as ``on_result(i, result)`` when job ``i`` finishes (after the journal).

    Returns:
        the results, one per job, in the order of ``jobs``.
    """
    from tqdm import tqdm

    if len(set(keys)) != len(keys):
        raise ValueError("run_jobs: job keys must be unique")
    done = dict(journal.done) if journal is not None else {}
    todo = [i for i, k in enumerate(keys) if k not in done]
    results: dict[int, object] = {i: done[k] for i, k in enumerate(keys) if k in done}
    sizes = [1] * len(jobs) if sizes is None else list(sizes)
    bar = tqdm(
        total=sum(sizes),
        initial=sum(sizes) - sum(sizes[i] for i in todo),
        desc=desc,
        unit="episode",
        leave=False,
        disable=not progress,
    )

    def finished(i: int, result) -> None:
        results[i] = result
        if journal is not None:
            journal.add(keys[i], result)
        if on_result is not None:
            on_result(i, result)
        bar.update(sizes[i])

    if journal is not None and journal.resumed and len(todo) < len(jobs):
        print(f"resuming {journal.path}: {len(jobs) - len(todo)} of {len(jobs)} {desc} already done", file=sys.stderr)
    try:
        if ray is None and (workers or 1) > 1 and len(todo) > 1:
            pool = local_pool(workers)
            pending = {pool.submit(fn, jobs[i]): i for i in todo}
            for future in as_completed(pending):
                finished(pending[future], future.result())
        elif ray is None:
            for i in todo:
                finished(i, fn(jobs[i]))
        else:
            _run_on_ray(fn, jobs, keys, todo, finished, ray, max_retries)
    finally:
        bar.close()
    return [results[i] for i in range(len(jobs))]


_POOLS: dict[int, ProcessPoolExecutor] = {}


def local_pool(workers: int) -> ProcessPoolExecutor:
    """A pool of ``workers`` processes, started once per process and kept (its workers keep
    their imports and compiled kernels from one call to the next). Workers are spawned, not
    forked: a fork would copy this process's thread pools (numba's, torch's) mid-state. A worker
    exits when this process does, however it ends (:func:`_exit_with_parent`)."""
    if workers not in _POOLS:
        _POOLS[workers] = ProcessPoolExecutor(
            workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_exit_with_parent,
            initargs=(os.getpid(),),
        )
    return _POOLS[workers]


def _exit_with_parent(parent: int, every_s: float = 1.0) -> None:
    """In a pool worker: a daemon thread that ends the worker once ``parent`` is gone (killed, it
    leaves no one to collect a result, and a judge's batch of long episodes would run on for an
    hour)."""

    def watch():
        while os.getppid() == parent:
            time.sleep(every_s)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def _attempt(fn, job, key: str, ledger):
    """The Ray task: note the attempt in the ledger, then run the job.

    The note is sent without waiting for its answer: a task blocked in ``ray.get`` gives its
    CPU back, and Ray then starts another worker process for the next task, which pays for
    the imports and the JIT cache again (that made Ray slower than serial on two cores).
    """
    ledger.start.remote(key)
    return fn(job)


class _Ledger:
    """A Ray actor counting the attempts of each task (more than one: Ray retried it)."""

    def __init__(self):
        self.attempts: dict[str, int] = {}

    def start(self, key: str) -> int:
        self.attempts[key] = self.attempts.get(key, 0) + 1
        return self.attempts[key]

    def retried(self) -> dict[str, int]:
        return {k: n - 1 for k, n in self.attempts.items() if n > 1}

    def clear(self) -> None:
        self.attempts.clear()


def _ledger(ray):
    """The driver's ledger actor, started and empty.

    One ledger per driver, kept between runs: an actor is a process of its own, and starting one
    per run costs about a second of CPU, which two cores feel. A kept ledger whose process has
    died since (Ray reports it when the next run clears it) is replaced by a new one under a new
    name; the ledger only counts retries, so no result depends on it.
    """
    job = ray.get_runtime_context().get_job_id()
    for attempt in range(3):
        name = f"proteo-ledger-{job}" + (f"-{attempt}" if attempt else "")
        ledger = ray.remote(num_cpus=0)(_Ledger).options(name=name, get_if_exists=True).remote()
        try:
            ray.get(ledger.clear.remote())  # started, and empty, before any task needs it
            return ledger
        except ray.exceptions.RayActorError:
            continue
    raise RuntimeError("Ray could not start the ledger actor three times; see Ray's logs (ray status)")


def _run_on_ray(fn, jobs, keys, todo, finished, options: dict, max_retries: int) -> None:
    ray = connect(**options)
    ledger = _ledger(ray)
    task = ray.remote(num_cpus=1, max_retries=max_retries, retry_exceptions=False)(_attempt)
    slots = options.get("workers") or max(1, int(ray.cluster_resources().get("CPU", 1)))
    pending: dict = {}
    queue = list(todo)
    try:
        while queue or pending:
            while queue and len(pending) < 2 * slots:  # a short queue per CPU hides the scheduling latency
                i = queue.pop(0)
                pending[task.remote(fn, jobs[i], keys[i], ledger)] = i
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                i = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except ray.exceptions.RayTaskError as err:  # the job itself failed: its own error
                    cause = err.as_instanceof_cause()
                    raise (cause.cause if getattr(cause, "cause", None) is not None else cause) from None
                except (ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError) as err:
                    raise RuntimeError(
                        f"job {keys[i]!r} failed: its worker died {max_retries + 1} times "
                        f"({type(err).__name__}); the finished jobs are kept, rerun the same "
                        "command to resume"
                    ) from None
                finished(i, result)
    finally:
        try:
            retried = ray.get(ledger.retried.remote())
        except ray.exceptions.RayActorError:  # the ledger's process died: the count is lost, not the results
            retried = {}
        if retried:
            print(
                f"ray: {len(retried)} task(s) retried after their worker died: "
                + ", ".join(f"{k} ({n}x)" for k, n in sorted(retried.items())),
                file=sys.stderr,
            )
        for ref in pending:
            ray.cancel(ref)


# ---------------------------------------------------------------------- connecting
def require_ray():
    """The ``ray`` module, or a :class:`ClusterError` saying how to install it."""
    try:
        import ray
    except ImportError:
        raise ClusterError(
            "--ray needs Ray, which is not installed; allowed: pip install -c constraints.txt "
            "-e '.[distributed]' (ray 2.60.0)"
        ) from None
    return ray


def _check_reachable(address: str) -> None:
    """A quick TCP connection to ``HOST:PORT`` (Ray's own connection attempts take minutes to give up)."""
    if address == "auto":
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ClusterError(
            f"--address {address!r} is not allowed; allowed: HOST:PORT of a Ray head node "
            "(as printed by `ray start --head`, e.g. 10.0.0.5:6379), ray://HOST:PORT, or 'auto'"
        )
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
    except OSError as err:
        raise ClusterError(
            f"--address {address!r}: no Ray head node answers there ({err.strerror or err}); "
            "allowed: the address printed by `ray start --head` on a running head node, or no "
            "--address for a local Ray instance"
        ) from None


def connect(address: str | None = None, workers: int | None = None):
    """Connect to Ray (once per process) and check that every node can run the project.

    ``address=None`` starts a local instance of this process's own with ``workers`` CPUs (default:
    all), never joining one that another process started on the machine (``ray start``, another
    run); an address joins a running cluster. An already initialised Ray (a test's cluster) is
    used as it is.
    Returns the ``ray`` module.
    """
    ray = require_ray()
    if not ray.is_initialized():
        if address is not None:
            _check_reachable(address)
            try:
                ray.init(address=address, include_dashboard=False, log_to_driver=False)
            except (ConnectionError, RuntimeError, ValueError) as err:
                raise ClusterError(
                    f"--address {address!r}: cannot join the Ray cluster there ({err}); allowed: "
                    "the address printed by `ray start --head`, reached with the same Ray version "
                    f"({ray.__version__})"
                ) from None
        else:
            ray.init(address="local", num_cpus=workers, include_dashboard=False, log_to_driver=False)
        check_cluster()
    return ray


def project_fingerprint() -> str:
    """A hash of the project's Python sources (the same on every node of a consistent cluster)."""
    digest = hashlib.sha256()
    for name in PROJECT_MODULES:
        module = sys.modules.get(name) or __import__(name)
        root = Path(module.__file__).parent
        for file in sorted(root.rglob("*.py")):
            digest.update(file.relative_to(root.parent).as_posix().encode())
            digest.update(file.read_bytes())
    return digest.hexdigest()[:16]


def _probe(modules: tuple[str, ...]) -> dict:
    """Run on one node: which project modules import there, and the project's fingerprint."""
    out = {"host": socket.gethostname(), "missing": {}}
    for name in modules:
        try:
            importlib.import_module(name)
        except Exception as err:  # noqa: BLE001 - any import failure means the node cannot run jobs
            out["missing"][name] = f"{type(err).__name__}: {err}"
    out["fingerprint"] = None if out["missing"] else project_fingerprint()
    return out


def check_cluster(modules: tuple[str, ...] = PROJECT_MODULES) -> list[dict]:
    """Run :func:`_probe` on every alive node; a node lacking the project (or running other
    code than this one) is a :class:`ClusterError` that names it. Returns the probes."""
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    probe = ray.remote(num_cpus=0, max_retries=0)(_probe)
    nodes = [n for n in ray.nodes() if n.get("Alive")]
    refs = [
        probe.options(scheduling_strategy=NodeAffinitySchedulingStrategy(n["NodeID"], soft=False)).remote(modules)
        for n in nodes
    ]
    probes, problems = [], []
    mine = project_fingerprint()
    for node, ref in zip(nodes, refs):
        where = f"node {node['NodeManagerAddress']} ({node['NodeID'][:8]})"
        try:
            found = ray.get(ref, timeout=120)
        except Exception as err:  # noqa: BLE001 - a worker that cannot even unpickle the probe
            problems.append(f"{where}: cannot run a task ({type(err).__name__}: {str(err).splitlines()[0]})")
            continue
        probes.append(found)
        if found["missing"]:
            problems += [f"{where}: cannot import {name} ({why})" for name, why in found["missing"].items()]
        elif found["fingerprint"] != mine:
            problems.append(f"{where}: runs other proteo code (sources {found['fingerprint']}, here {mine})")
    if problems:
        raise ClusterError(
            "the Ray cluster cannot run proteo's jobs: " + "; ".join(problems) + "; allowed: every "
            "node with this checkout installed (pip install -c constraints.txt -e '.[distributed]') "
            "and its workers started from that environment"
        )
    return probes
