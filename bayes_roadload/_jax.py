"""JAX settings of the package, applied once when :mod:`bayes_roadload` is first imported.

* **64-bit floats** (``jax_enable_x64``): coastdown forces are small differences of large
  quantities (the speed changes by ~1e-3 m/s per 0.25 s sample against 30 m/s), and the NUTS
  energy error and the RK4 integration lose their accuracy in 32 bits.
* **One XLA host device per CPU core** (``--xla_force_host_platform_device_count`` in
  ``XLA_FLAGS``): numpyro runs its chains in parallel (``chain_method="parallel"``,
  :func:`bayes_roadload.inference.nuts.chain_method`) only when ``jax.local_device_count()``
  is at least the number of chains.  XLA reads the flag when its CPU backend starts, so it must
  be set before the first JAX computation of the process.

To override: set ``XLA_FLAGS`` with your own ``--xla_force_host_platform_device_count=N``
before importing the package (it is then left as it is), or call
``jax.config.update("jax_enable_x64", False)`` afterwards (not recommended: the fits are
tested in 64 bits only).  A JAX backend that has already started when the package is imported
keeps its device count.
"""

from __future__ import annotations

import os

DEVICE_COUNT_FLAG = "--xla_force_host_platform_device_count"


def configure_jax() -> None:
    """Set the device-count XLA flag (unless ``XLA_FLAGS`` already names one) and enable x64."""
    flags = os.environ.get("XLA_FLAGS", "")
    if DEVICE_COUNT_FLAG.lstrip("-") not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} {DEVICE_COUNT_FLAG}={max(os.cpu_count() or 1, 1)}".strip()
    import jax  # after XLA_FLAGS: the backend reads it when it starts

    jax.config.update("jax_enable_x64", True)



CACHE_ENV = "BAYES_ROADLOAD_CACHE_DIR"
"""Environment variable: the persistent compilation cache's directory ("" turns it off)."""
CACHE_MIN_COMPILE_S = 0.2
"""Programs that took at least this long to compile are cached (JAX's default, 1 s, leaves out
the many 0.2-1 s programs of a fit: the likelihood's value, gradient and predictive)."""


def default_cache_dir() -> str:
    """``$XDG_CACHE_HOME/bayes-roadload/jax`` (``~/.cache/bayes-roadload/jax`` without it)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "bayes-roadload", "jax")


def enable_compilation_cache(path: str | None = None) -> str | None:
    """Turn on JAX's persistent compilation cache so that a command run again on same-shaped data
    loads its compiled programs instead of compiling them (the command line does this on start).

    ``path``: the cache directory; default ``$BAYES_ROADLOAD_CACHE_DIR``, else
    :func:`default_cache_dir`; an empty ``$BAYES_ROADLOAD_CACHE_DIR`` turns the cache off.
    ``$BAYES_ROADLOAD_CACHE_DIR_MIN_COMPILE_S`` overrides :data:`CACHE_MIN_COMPILE_S` (0: cache
    every program).
    The cache holds compiled code that the process will run: keep it in a directory only you can
    write.  Returns the directory used, or None (off, or not writable).
    """
    import jax

    path = path if path is not None else os.environ.get(CACHE_ENV, default_cache_dir())
    if not path:
        return None
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    min_s = float(os.environ.get(CACHE_ENV + "_MIN_COMPILE_S", CACHE_MIN_COMPILE_S))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", min_s)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path


configure_jax()
