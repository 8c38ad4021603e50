"""What a benchmark ran on: the JAX backend and device kind, core count and load, library versions.

Every `protamer bench ... --json` result carries this, so a figure says which machine (CPU or which GPU) and
how busy it was; a GPU figure and a CPU figure can then never be confused in the docs.
"""

from __future__ import annotations

import os
import platform


def describe() -> dict:
    import jax

    devices = jax.local_devices()
    return {
        "jax_backend": jax.default_backend(),
        "devices": len(devices),
        "device_kind": devices[0].device_kind if devices else None,
        "cpu_count": os.cpu_count(),
        "processor": platform.processor() or platform.machine(),
        "cpu_model": cpu_model(),
        "loadavg": list(os.getloadavg()),
        "jax_version": jax.__version__,
        "python": platform.python_version(),
    }


def cpu_model() -> str | None:
    """The CPU's model name (Linux: /proc/cpuinfo), or None. XLA compiles for the host's instruction set, so a
    run's rounding, and with it every seed's trajectory, can differ from one CPU model to another."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None
