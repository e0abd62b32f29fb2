"""Shared fixtures: small simulated campaigns and one NUTS fit reused by many tests.

The test processes (and the command-line subprocesses they start) compile with LLVM's
expensive optimisation passes off (``--xla_llvm_disable_expensive_passes``): the suite
compiles hundreds of programs that each run for a few small draws, and compilation was over
half of its time.  XLA's CPU backend does not enable fast-math, so the arithmetic is the same
(a potential and its gradient came out bit-identical with and without the flag); only the
machine code is less optimised.  Set ``XLA_FLAGS`` yourself to run the suite otherwise.
"""

import contextlib
import dataclasses
import importlib.util
import logging
import os
import shutil
import sys
import tempfile
import warnings
from pathlib import Path

if "XLA_FLAGS" not in os.environ:  # before bayes_roadload starts JAX (its device-count flag is added)
    os.environ["XLA_FLAGS"] = "--xla_llvm_disable_expensive_passes=true"

import pytest  # noqa: E402

from bayes_roadload import config, console  # noqa: E402
from bayes_roadload.simulate import get_case, simulate_campaign  # noqa: E402



def pytest_configure(config):
    """One fresh persistent compilation cache for the whole run, shared by the worker processes
    and the command-line subprocesses (they inherit the environment): the suite compiles many
    identical programs in separate closures and processes.  Fresh per run, so a run never
    starts warm from an earlier one; removed at the end.  Every program is cached, however short
    its compilation (the package's threshold, 0.2 s, leaves out the ~95 small programs of a fit's
    eagerly run operations, ~3 s of compilation per process)."""
    if hasattr(config, "workerinput") or "BAYES_ROADLOAD_CACHE_DIR" in os.environ:
        return
    path = tempfile.mkdtemp(prefix="bayes-roadload-test-cache-")
    os.environ["BAYES_ROADLOAD_CACHE_DIR"] = path
    os.environ.setdefault("BAYES_ROADLOAD_CACHE_DIR_MIN_COMPILE_S", "0")
    config._bayes_roadload_cache = path


LONGEST_FIRST = (
    "tests/output/test_report.py",  # computes the shared command-line fit (cli_nuts_fit) ...
    "tests/inference/test_nuts.py",  # ... and the shared NUTS fit (pooled_fit)
    "tests/analysis/test_budget.py",
    "tests/physics/test_integrate.py",
    "tests/inference/test_calibration_model.py",
    "tests/inference/test_lsq.py",
    "tests/analysis/test_calibration.py",
    "tests/simulate/test_campaign.py",
    "tests/inference/test_bayes.py",
    "tests/test_cli_demo_and_plan.py",
    "tests/analysis/test_diagnose.py",
    "tests/test_cli.py",  # reads cli_nuts_fit: after test_report has started it
    "tests/test_notebooks.py",  # likewise
)
"""Test modules that took 40-100 s each in the default run (``--durations``, 2 workers), in
the order the two workers are handed them: longest first, so that the run does not end with one
worker on a long module while the other waits (--no-loadscope-reorder in pyproject.toml keeps
this order; xdist's own reorder is by number of tests).  The other modules follow in their
collection order."""


def pytest_collection_modifyitems(config, items):
    """Modules in :data:`LONGEST_FIRST` order, then the rest as collected (stable)."""
    rank = {path: i for i, path in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::", 1)[0], len(rank)))


def pytest_unconfigure(config):
    path = getattr(config, "_bayes_roadload_cache", None)
    if path:
        shutil.rmtree(path, ignore_errors=True)
        os.environ.pop("BAYES_ROADLOAD_CACHE_DIR", None)


@pytest.fixture(scope="session", autouse=True)
def compilation_cache():
    """The run's compilation cache in this process too (:func:`pytest_configure`)."""
    from bayes_roadload._jax import enable_compilation_cache

    enable_compilation_cache()
    yield


_PACKAGE_LOGGER = logging.getLogger(console.PACKAGE_LOGGER)
_PRISTINE_LOGGER = (list(_PACKAGE_LOGGER.handlers), _PACKAGE_LOGGER.level, _PACKAGE_LOGGER.propagate)
"""The package logger's handlers, level and propagation as the test process imported it,
before any command configured it."""


@pytest.fixture(autouse=True)
def package_logger_as_imported():
    """The ``bayes_roadload`` logger set back to its state at import (:data:`_PRISTINE_LOGGER`)
    before and after every test.  A command run in process (``cli.main``) configures it for a
    terminal (``console.configure``: its own handlers, ``propagate = False``), and every later
    test of the same worker that reads log records with ``caplog`` (which listens at the root
    logger) then saw none.  Reset at set-up too: a session fixture that runs a command (e.g.
    the shared command-line fit) does so while the first test that asks for it is set up,
    after an autouse fixture of the test's own scope could have saved the state."""
    def reset():
        handlers, level, propagate = _PRISTINE_LOGGER
        _PACKAGE_LOGGER.handlers[:] = handlers
        _PACKAGE_LOGGER.setLevel(level)
        _PACKAGE_LOGGER.propagate = propagate

    reset()
    yield
    reset()


SMALL_SAMPLER = config.SamplerConfig(num_warmup=300, num_samples=800, num_chains=2, seed=3, target_accept=0.95)
"""Small draw counts for tests, and what a two-pair campaign needs to pass the gates: with
2 x 400 draws (bulk ESS ~300) the max split R-hat over the 13 unknowns came out 1.007-1.013
across seeds; at the default target acceptance 0.9 1-3 of 1600 draws diverge where the
integrated-noise level q is small (two pairs barely identify q).  The CLI prints that remedy
(--target-accept 0.95) when the divergence gate fails."""


def clean_case():
    """Case 2 winds (2/2 m/s), basic drag model, no instrument dynamics, measurement noise on,
    system noise off: the analysis model is correctly specified but for the input noise."""
    return dataclasses.replace(get_case(2), model="basic", dynamics=False, measurement_noise=True,
                               system_noise=False)


@pytest.fixture(scope="session", autouse=True)
def keep_compiled_code():
    """The test process runs hundreds of small fits whose compiled pieces later tests reuse
    (e.g. the planning refits of one campaign shape): clearing JAX's caches once the process
    passes 4 GB (the batch door's default for long studies) made later tests recompile.  The
    suite stays well inside the CI machine's memory without it."""
    from bayes_roadload.analysis import batch

    before = batch.CLEAR_JAX_CACHES_ABOVE_MB
    batch.CLEAR_JAX_CACHES_ABOVE_MB = 12288.0
    yield
    batch.CLEAR_JAX_CACHES_ABOVE_MB = before


@pytest.fixture(scope="session")
def small_campaign():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return simulate_campaign(clean_case(), pairs=2, seed=11)


def computed_once(request, tmp_path_factory, name: str, compute):
    """``compute()``, shared by the run's worker processes: the first worker to need it computes
    it and leaves it pickled in the run's base directory, where a later worker reads it.  A
    worker that needs it while another is computing it waits for it (computing its own copy
    alongside took the other worker's core: the suite's CPU is saturated); it computes its own
    only when the first left no file (its computation raised).  ``compute`` must not call
    :func:`computed_once` itself: two workers each holding one lock and waiting for the other's
    would wait for ever."""
    worker_id = getattr(request.config, "workerinput", {}).get("workerid")
    if worker_id is None:  # one process: the session fixture alone shares it
        return compute()
    import fcntl
    import pickle

    root = tmp_path_factory.getbasetemp().parent  # one per run, shared by its workers
    data = root / f"{name}.pickle"
    if data.is_file():
        return pickle.loads(data.read_bytes())
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the holder finishes, or its process ends
        if data.is_file():  # written by the worker that held the lock before
            return pickle.loads(data.read_bytes())
        value = compute()
        tmp = data.with_suffix(f".{worker_id}")
        tmp.write_bytes(pickle.dumps(value))
        tmp.replace(data)  # a reader sees the whole file or none
        return value


CLI_NUTS_FIT = ["--model", "four_term", "--pooling", "pooled", "--warmup", "100", "--draws", "100"]
"""The options of the run's shared command-line NUTS fit (:func:`cli_nuts_fit`)."""


@dataclasses.dataclass(frozen=True)
class CliFit:
    """A ``bayes-roadload fit`` run: its exit code, what it printed and its fit directory."""

    code: int
    out: str
    err: str
    fit_dir: Path


@pytest.fixture(scope="session")
def cli_nuts_fit(request, tmp_path_factory) -> CliFit:
    """``simulate --case 14 --pairs 2 --seed 1`` then ``fit`` with :data:`CLI_NUTS_FIT` (the
    default report and Type B budget), through the command line, computed once per run
    (:func:`computed_once`) and read by the tests of the command line, the report and the
    notebooks on a user's fit.  Tests copy the directory before changing anything in it."""
    import contextlib
    import io

    from bayes_roadload.cli import main

    def compute() -> CliFit:
        root = tmp_path_factory.mktemp("cli_nuts_fit")
        assert main(["simulate", "--case", "14", "--pairs", "2", "--seed", "1", "--out", str(root / "c"), "-q"]) == 0
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(["fit", str(root / "c"), *CLI_NUTS_FIT, "--out", str(root / "f")])
        return CliFit(code, out.getvalue(), err.getvalue(), root / "f")

    return computed_once(request, tmp_path_factory, "cli_nuts_fit", compute)


@pytest.fixture(scope="session")
def pooled_fit(small_campaign, request, tmp_path_factory):
    """The NUTS fit of ``small_campaign`` (four-term, pooled, :data:`SMALL_SAMPLER`), computed
    once per run (:func:`computed_once`)."""
    from bayes_roadload.inference.nuts import fit_nuts

    return computed_once(request, tmp_path_factory, "pooled_fit",
                         lambda: fit_nuts(small_campaign, "four_term", sampler=SMALL_SAMPLER))


BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
"""The benchmark scripts' folder."""


@contextlib.contextmanager
def benchmark_script(name: str):
    """``benchmarks/<name>.py`` imported as a module, registered in ``sys.modules`` while in use
    (its dataclasses look their module up) and removed after; the benchmarks' folder is on
    ``sys.path`` meanwhile, as it is for a script run from it (its sibling modules, e.g.
    ``doc_sections``, import)."""
    path = BENCHMARKS / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"{name}_benchmark", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    added = str(BENCHMARKS) not in sys.path
    if added:
        sys.path.insert(0, str(BENCHMARKS))
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)
        if added and str(BENCHMARKS) in sys.path:
            sys.path.remove(str(BENCHMARKS))


def with_fixed(spec, values: dict[str, float]):
    """``spec`` with the free parameters ``values`` fixed at those values (SI): the reference
    the held least-squares fits (``fit_lsq(..., hold=...)``) are checked against."""
    import dataclasses

    return dataclasses.replace(spec, free=tuple(p for p in spec.free if p not in values),
                               fixed={**spec.fixed, **values},
                               priors={k: v for k, v in spec.priors.items() if k not in values},
                               initial={k: v for k, v in spec.initial.items() if k not in values})
