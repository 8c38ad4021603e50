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
        "loadavg": list(os.getloadavg()),
        "jax_version": jax.__version__,
        "python": platform.python_version(),
    }
