"""JAX settings of the package, applied once when :mod:`bayes_roadload` is first imported.

* **64-bit floats** (``jax_enable_x64``): coastdown forces are small differences of large
  quantities (the speed changes by ~1e-3 m/s per 0.25 s sample against 30 m/s), and the NUTS
  energy error and the RK4 integration lose their accuracy in 32 bits.
* **One XLA host device per CPU core** (``--xla_force_host_platform_device_count`` in
  ``XLA_FLAGS``): numpyro runs its chains in parallel (``chain_method="parallel"``,
  :func:`bayes_roadload.inference.nuts.chain_method`) only when ``jax.local_device_count()``
  is at least the number of chains.  XLA reads the flag when its CPU backend starts, so it must
  be set before the first JAX computation of the process.
* **At most two glibc malloc arenas** (``mallopt(M_ARENA_MAX, 2)``, :func:`limit_malloc_arenas`):
  glibc gives each allocating thread its own arena, up to 8 per core, and an arena keeps its
  high-water mark.  XLA's CPU threads allocate and free temporaries while NUTS runs: at 18
  pairs the resident memory while sampling peaked at 1132 MB with glibc's default and at 944 MB
  with two arenas (docs/performance.md, section *Memory*).  Linux with glibc only;
  ``MALLOC_ARENA_MAX`` in the environment, or ``BAYES_ROADLOAD_MALLOC_ARENAS`` (0: glibc's
  default), wins.
* **Programs shared across same-shaped campaigns, on request** (``BAYES_ROADLOAD_SHARE_PROGRAMS=1``,
  :func:`share_programs`): JAX then hoists every non-scalar array a jitted function closes over
  into an argument (``jax_use_simplified_jaxpr_constants``, ``jax_embedded_constants_max_bytes``
  = 0: :data:`SHARED_PROGRAM_FLAGS`) and runs are padded to a few lengths
  (:data:`~bayes_roadload.config.PAD_SIZES_PER_OCTAVE`), so campaigns of the same number of runs
  and nearly the same length lower to the same programs and the persistent compilation cache
  (:func:`enable_compilation_cache`) serves them: a second 2-pair fit took 7.9 s instead of
  22.2 s.  Off by default: with the data as arguments the warm-up and sampling of a 36-run fit
  ran 29 % longer (63.0 s against 48.8 s, same draws and steps; ``benchmarks/shared_programs.py``;
  likely XLA no longer folding data-only arithmetic into constants).  JAX reads the options when it
  is imported, so they are set as environment variables before the package imports JAX; a value
  already in the environment wins, and a process that imported JAX first keeps JAX's defaults.

To override: set ``XLA_FLAGS`` with your own ``--xla_force_host_platform_device_count=N``
before importing the package (it is then left as it is), or call
``jax.config.update("jax_enable_x64", False)`` afterwards (not recommended: the fits are
tested in 64 bits only).  A JAX backend that has already started when the package is imported
keeps its device count.
"""

from __future__ import annotations

import os
import sys

DEVICE_COUNT_FLAG = "--xla_force_host_platform_device_count"
MALLOC_ARENAS = 2
"""glibc malloc arenas of the process (:func:`limit_malloc_arenas`)."""
ARENAS_ENV = "BAYES_ROADLOAD_MALLOC_ARENAS"
_M_ARENA_MAX = -8
"""glibc's ``mallopt`` parameter number of ``M_ARENA_MAX`` (malloc.h)."""


def limit_malloc_arenas(n: int | None = None) -> int | None:
    """Cap glibc's malloc arenas at ``n`` (default ``$BAYES_ROADLOAD_MALLOC_ARENAS``, else
    :data:`MALLOC_ARENAS`) with ``mallopt(M_ARENA_MAX, n)``, so that the resident memory of a
    long NUTS run does not ratchet up with each XLA thread's high-water mark (module docstring).
    Arenas already attached to running threads are kept; threads started later share the ``n``.

    Returns the cap set, or None when nothing was done: not Linux with glibc, ``MALLOC_ARENA_MAX``
    set in the environment (glibc read it at start), or ``n`` = 0 (or
    ``$BAYES_ROADLOAD_MALLOC_ARENAS`` not an integer).
    """
    import ctypes
    import sys

    if n is None:
        try:
            n = int(os.environ.get(ARENAS_ENV, MALLOC_ARENAS))
        except ValueError:  # not a number: glibc's default, as for 0
            return None
    if n <= 0 or "MALLOC_ARENA_MAX" in os.environ or not sys.platform.startswith("linux"):
        return None
    try:
        if not (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc"):
            return None
        ok = ctypes.CDLL(None).mallopt(_M_ARENA_MAX, int(n))
    except (OSError, ValueError, AttributeError):
        return None
    return int(n) if ok == 1 else None


SHARED_PROGRAM_FLAGS = {"jax_use_simplified_jaxpr_constants": True, "jax_embedded_constants_max_bytes": 0}
"""JAX options that make compiled programs take closed-over arrays as arguments (module docstring)."""
SHARE_ENV = "BAYES_ROADLOAD_SHARE_PROGRAMS"
"""Environment variable: "1" shares compiled programs across same-shaped campaigns (module docstring)."""


def share_programs() -> bool:
    """Whether compiled programs are shared across same-shaped campaigns (``$BAYES_ROADLOAD_SHARE_PROGRAMS``
    is "1"; module docstring)."""
    return os.environ.get(SHARE_ENV, "") == "1"


def configure_jax() -> None:
    """Set the device-count XLA flag (unless ``XLA_FLAGS`` already names one), cap glibc's
    malloc arenas (:func:`limit_malloc_arenas`), enable x64 and, when :func:`share_programs`,
    hoist closed-over arrays into program arguments (:data:`SHARED_PROGRAM_FLAGS`)."""
    limit_malloc_arenas()
    flags = os.environ.get("XLA_FLAGS", "")
    if DEVICE_COUNT_FLAG.lstrip("-") not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} {DEVICE_COUNT_FLAG}={max(os.cpu_count() or 1, 1)}".strip()
    if share_programs() and "jax" not in sys.modules:  # JAX reads these when it is imported
        for name, value in SHARED_PROGRAM_FLAGS.items():
            os.environ.setdefault(name.upper(), str(value))
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


COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration",
                  "/jax/core/compile/jaxpr_to_mlir_module_duration",
                  "/jax/core/compile/backend_compile_duration")
"""JAX's monitoring events whose durations :func:`compile_seconds` sums: tracing a function to
a jaxpr, lowering it to MLIR and XLA compiling it (a program the persistent cache serves is
traced and lowered, not compiled)."""
_compile_total = [0.0]
_compile_listening = [False]


def _on_compile_event(event: str, duration_s: float, **_) -> None:
    if event in COMPILE_EVENTS:
        _compile_total[0] += duration_s


def compile_seconds() -> float:
    """Seconds this process has spent tracing, lowering and compiling JAX code since the first
    call (which starts listening to :data:`COMPILE_EVENTS`); the difference of two calls is the
    compilation inside a stage."""
    if not _compile_listening[0]:
        import jax.monitoring

        jax.monitoring.register_event_duration_secs_listener(_on_compile_event)
        _compile_listening[0] = True
    return _compile_total[0]


configure_jax()
