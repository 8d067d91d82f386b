"""What a benchmark ran on: one description shared by the scripts in ``benchmarks/``."""

from __future__ import annotations

import importlib
import os
import platform


def describe(*packages: str, **extra) -> dict:
    """CPU model, core count, load average, Python and the versions of ``packages``, plus ``extra``."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    info = {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load_average_1min": round(os.getloadavg()[0], 2),
        "python": platform.python_version(),
    }
    for name in packages:
        info[name] = importlib.import_module(name).__version__
    return {**info, **extra}
