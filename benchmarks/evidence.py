"""What every evidence script (``benchmarks/*_evidence.py``) shares, so that each keeps only its
episode function (one job in, one row out), its metrics and its tables: the per-seed job runner
(:func:`run_jobs`), the cells with intervals (from :mod:`training.judging.statistics`), the machine line
(from :mod:`machine_info`) and the writing of the page, whole (:func:`publish`) or its tables
between the ``<!-- tables -->`` markers (:func:`write_tables`).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from machine_info import describe

OPEN, CLOSE = "<!-- tables -->", "<!-- /tables -->"


# --------------------------------------------------------------------------- jobs
def _one_thread() -> None:
    """Worker initializer: one numba thread per worker process (the workers are the parallelism)."""
    os.environ["NUMBA_NUM_THREADS"] = "1"
    if "numba" in sys.modules:  # imported before the fork: its thread count is already read
        import numba

        numba.set_num_threads(1)


def run_jobs(episode: Callable, jobs: Iterable, workers: int = 1) -> Iterator:
    """``episode(job)`` for every job, yielded in the jobs' order as they come in.

    ``workers <= 1`` runs them here, one after the other; more runs them in that many processes
    (one job at a time each, one numba thread each). ``episode`` must be a module-level function
    (it is pickled by name). Every job is seeded, so the results do not depend on ``workers``.
    """
    jobs = list(jobs)
    if workers <= 1 or len(jobs) <= 1:
        yield from map(episode, jobs)
        return
    with ProcessPoolExecutor(min(workers, len(jobs)), initializer=_one_thread) as pool:
        yield from pool.map(episode, jobs, chunksize=1)


def add_workers(parser, default: int | None = None) -> None:
    """The ``--workers`` option (default: the number of CPUs)."""
    parser.add_argument(
        "--workers",
        type=int,
        default=default if default is not None else os.cpu_count() or 1,
        help="episodes run in parallel processes of one thread each (1: serially)",
    )


# --------------------------------------------------------------------------- intervals
def mean_cell(values) -> str:
    """``mean ± half-width`` of the 95 % Student t interval of the known values (``None`` left
    out; ``n/a`` when none is known, the mean alone for one); no decimals from 10 up, two below."""
    from training.judging.statistics import mean_ci

    v = [x for x in values if x is not None]
    if not v:
        return "n/a"
    mean, half = mean_ci(v)
    if len(v) == 1:
        return f"{mean:.0f}" if mean >= 10 else f"{mean:.2f}"
    fmt = "{:.0f} ± {:.0f}" if abs(mean) >= 10 else "{:.2f} ± {:.2f}"
    return fmt.format(mean, half)


def success_cell(k: int, n: int) -> str:
    """``k/n [low, high]``: successes over episodes and their 95 % Wilson interval."""
    from training.judging.statistics import wilson

    if n == 0:
        return "n/a"
    lo, hi = wilson(k, n)
    return f"{k}/{n} [{lo:.2f}, {hi:.2f}]"


# --------------------------------------------------------------------------- the page
def machine(workers: int | None = None, seconds: float | None = None, packages=("numpy", "numba")) -> str:
    """One line: CPU, CPUs, 1-minute load average, Python, ``packages``' versions, numba's
    threads, and, when given, the worker processes and the wall time."""
    info = describe(*packages)
    text = (
        f"{info['cpu']}, {info['cores']} CPUs, load average {info['load_average_1min']}, "
        f"Python {info['python']}, "
        + ", ".join(f"{name} {info[name]}" for name in packages)
        + f", NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'default')}"
    )
    if workers is not None:
        text += f", {workers} worker{'s' if workers != 1 else ''}" + (" of 1 thread" if workers > 1 else "")
    if seconds is not None:
        text += f", {seconds:.0f} s"
    return text


def arguments(argv=None) -> str:
    """The command-line arguments as typed (``argv``, else ``sys.argv[1:]``)."""
    return " ".join(sys.argv[1:] if argv is None else argv)


def command(script: str, argv=None) -> str:
    """``python benchmarks/SCRIPT ARGS``: the command a page records."""
    return f"python benchmarks/{script} {arguments(argv)}".rstrip()


def publish(text: str, out) -> None:
    """Write the page ``text`` to ``out`` (its folder made), or print it when ``out`` is None."""
    if out is None:
        print(text)
        return
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"wrote {out}")


def write_tables(path, block: str) -> None:
    """Put ``block`` between the ``<!-- tables -->`` markers of the page ``path`` (a page of
    just the markers when there is none), keeping everything around them."""
    path = Path(path)
    text = path.read_text() if path.exists() else f"{OPEN}\n{CLOSE}\n"
    head, rest = text.split(OPEN, 1)
    tail = rest.split(CLOSE, 1)[1]
    path.write_text(f"{head}{OPEN}\n{block}\n{CLOSE}{tail}")
