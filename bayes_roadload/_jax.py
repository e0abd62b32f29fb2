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


configure_jax()
