"""Log every XLA compilation of a process, keyed by the running test: imported at start-up by
``sitecustomize.py`` in this directory when it is on ``PYTHONPATH``, it appends one line per
compilation -- test id, program name, seconds -- to ``$SUITE_COMPILE_LOG`` (JAX's own debug
message "Finished XLA compilation of NAME in T sec").  pytest's worker processes and the
command-line subprocesses they start all inherit the environment, so the whole suite is seen.

    SUITE_COMPILE_LOG=/tmp/compile.tsv PYTHONPATH=benchmarks/suite_compile python -m pytest
    python benchmarks/suite_compile_summary.py /tmp/compile.tsv
"""
import logging
import os
import re

_PATTERN = re.compile(r"Finished XLA compilation of (.*) in ([0-9.e-]+) sec")


class _Handler(logging.Handler):
    def emit(self, record):
        m = _PATTERN.search(record.getMessage())
        if m:
            test = os.environ.get("PYTEST_CURRENT_TEST", "?").split(" ")[0]
            with open(os.environ.get("SUITE_COMPILE_LOG", "/tmp/suite_compile.tsv"), "a") as f:
                f.write(f"{test}\t{m.group(1)}\t{m.group(2)}\n")


for _name in ("jax._src.dispatch", "jax._src.interpreters.pxla", "jax._src.compiler"):
    _logger = logging.getLogger(_name)
    _logger.setLevel(logging.DEBUG)
    _logger.addHandler(_Handler())
