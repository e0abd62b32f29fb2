"""The package caps glibc's malloc arenas on import (:func:`bayes_roadload._jax.limit_malloc_arenas`).

Counted with glibc's own ``malloc_info``: eight threads that allocate at the same time get an
arena each without the cap, and share two with it.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from bayes_roadload import _jax

glibc = sys.platform.startswith("linux") and (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc")
pytestmark = pytest.mark.skipif(not glibc, reason="mallopt(M_ARENA_MAX) is glibc's")

COUNT_ARENAS = r"""
import ctypes, re, sys, tempfile, threading
if sys.argv[1] == "import":
    import bayes_roadload  # noqa: F401
libc = ctypes.CDLL(None)
keep, start, done = [], threading.Barrier(9), threading.Barrier(9)
def work():
    start.wait()
    keep.append([bytearray(60_000) for _ in range(20)])  # below the mmap threshold: from an arena
    done.wait()
threads = [threading.Thread(target=work) for _ in range(8)]
for t in threads:
    t.start()
start.wait()
libc.fopen.restype = ctypes.c_void_p
path = tempfile.mktemp()
f = libc.fopen(path.encode(), b"w")
libc.malloc_info(0, ctypes.c_void_p(f))
libc.fclose(ctypes.c_void_p(f))
done.wait()
print(len(re.findall(r'<heap nr="\d+"', open(path).read())))
"""


def _arenas(mode: str, **env: str) -> int:
    environ = {k: v for k, v in os.environ.items() if k not in ("MALLOC_ARENA_MAX", _jax.ARENAS_ENV)}
    out = subprocess.run([sys.executable, "-c", COUNT_ARENAS, mode], env={**environ, **env},
                         capture_output=True, text=True, check=True)
    return int(out.stdout.split()[-1])


def test_importing_the_package_caps_the_arenas_of_concurrent_threads():
    without = _arenas("bare")
    assert without > _jax.MALLOC_ARENAS  # the check can fail: glibc gives each thread its own
    assert _arenas("import") == _jax.MALLOC_ARENAS


def test_the_environment_overrides_the_cap():
    assert _arenas("import", **{_jax.ARENAS_ENV: "0"}) > _jax.MALLOC_ARENAS
    assert _arenas("import", **{_jax.ARENAS_ENV: "3"}) == 3
    assert _arenas("import", **{_jax.ARENAS_ENV: "two"}) > _jax.MALLOC_ARENAS  # not a number: no cap, no error
    assert _jax.limit_malloc_arenas(0) is None


def test_a_user_malloc_arena_max_is_left_to_glibc():
    assert _arenas("import", MALLOC_ARENA_MAX="4") == 4
