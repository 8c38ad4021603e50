"""Shared test setup: a persistent JAX compilation cache so repeated runs skip most compiles.

JAX compiles are 10-50 s per shape on a 2-core CPU: tests share fixtures (see each folder's conftest)
and keep the number of distinct compiled shapes small.
"""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault(
    "JAX_COMPILATION_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "mjx_protamer", "jax")
)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "1")
