"""bayes-roadload: road load from coastdown tests, with honest uncertainty.

Layers: :mod:`physics` (pure JAX) -> :mod:`simulate` -> :mod:`inference` -> :mod:`analysis`
-> :mod:`data` / :mod:`cli`.  Importing the package enables 64-bit floats in JAX and one XLA
host device per CPU core, for parallel chains (:mod:`bayes_roadload._jax`).
"""

import time as _time

IMPORT_STARTED = _time.perf_counter()
"""When the package's import began (``time.perf_counter``): a command's ``imports_s``."""

from . import _jax  # noqa: E402, F401 -- first: sets XLA_FLAGS and x64 before any JAX computation
from . import config as config  # noqa: E402
from .physics import DragModel as DragModel  # noqa: E402
from .physics import full_model as full_model  # noqa: E402
from .physics import integrate_batch as integrate_batch  # noqa: E402
from .physics import integrate_run as integrate_run  # noqa: E402
from .physics import simplified_model as simplified_model  # noqa: E402

__version__ = "0.1.0"
"""The package version; pyproject.toml reads it from here (the one place it is written)."""
