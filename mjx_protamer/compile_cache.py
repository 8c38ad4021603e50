"""The persistent XLA compile cache every command and the live session turn on (the self-touch chunk takes minutes
to compile on 2 CPU cores; a second run of the same shapes starts in seconds)."""

from __future__ import annotations

import os


def enable() -> None:
    """Persist compiles under ~/.cache/mjx_protamer/jax; JAX_COMPILATION_CACHE_DIR, when set, wins."""
    import jax

    if not os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        jax.config.update("jax_compilation_cache_dir",
                          os.path.join(os.path.expanduser("~"), ".cache", "mjx_protamer", "jax"))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
