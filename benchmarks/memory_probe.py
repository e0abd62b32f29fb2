"""Where does resident memory grow while NUTS samples?  Three probes, each in its own process
(``ru_maxrss`` after the run less before it, MB), on the 18-pair reference campaign of
``benchmarks/cold_start.py`` (model four_term, pooled, the unconstrained potential scaled to
O(1)):

* ``gradient``: the potential's gradient 200 and 2000 times in one ``fori_loop``;
* ``gaussian``: numpyro NUTS (2 chains, ``chain_method="parallel"``) on a Gaussian potential of
  the same dimension, 2 x 100 and 2 x 1000 draws;
* ``nuts``: numpyro NUTS on the campaign's potential, 2 x 50 and 2 x 500 draws, for each
  ``chain_method`` (parallel, sequential, vectorized).

A peak that grows with the number of iterations points at the probe's component.  Records:
``benchmarks/records/performance/memory_probe.json``.

    python benchmarks/memory_probe.py
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "performance" / "memory_probe.json"

CHILD = r'''
import sys, warnings, resource, json
sys.path.insert(0, sys.argv[1])
warnings.simplefilter("ignore")
from bayes_roadload._jax import configure_jax
configure_jax()
import jax, jax.numpy as jnp, numpy as np
from jax.flatten_util import ravel_pytree
from numpyro.infer import MCMC, NUTS
from bayes_roadload.data import load_campaign
from bayes_roadload.inference.bayes import build_problem
from bayes_roadload.inference.nuts import prepare_problem, unconstrained_posterior
probe, n, method, camp = sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5]
c = load_campaign(camp)
p, init = prepare_problem(build_problem(c, "four_term", pooling="pooled"), c)
post = unconstrained_posterior(p, init)
flat0, unravel = ravel_pytree(post.z0)
d = flat0.size
pot = lambda u: post.potential_fn(unravel(flat0 + post.scale * u))
rss = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
if probe == "gradient":
    g = jax.grad(pot)
    loop = jax.jit(lambda x: jax.lax.fori_loop(0, n, lambda i, x: x - 1e-9 * g(x), x))
    loop(jnp.zeros(d)).block_until_ready()
    r0 = rss(); loop(jnp.zeros(d)).block_until_ready()
else:
    if probe == "gaussian":
        rng = np.random.default_rng(0)
        a = rng.normal(size=(d, d)); prec = jnp.asarray(np.linalg.inv(a @ a.T / d + np.eye(d)))
        pot = lambda u: 0.5 * u @ prec @ u
    m = MCMC(NUTS(potential_fn=pot, dense_mass=False), num_warmup=50, num_samples=n, num_chains=2,
             chain_method=method, progress_bar=False)
    r0 = rss(); m.run(jax.random.PRNGKey(0), init_params=jnp.zeros((2, d)))
print("RECORD " + json.dumps({"probe": probe, "iterations": n, "chain_method": method, "dimension": int(d),
                              "growth_mb": round(rss() - r0, 1)}))
'''

PROBES = [("gradient", 200, "-"), ("gradient", 2000, "-"), ("gaussian", 100, "parallel"), ("gaussian", 1000, "parallel")]
PROBES += [("nuts", n, m) for m in ("parallel", "sequential", "vectorized") for n in (50, 500)]


def main() -> None:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import cold_start

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        camp = cold_start.campaign(18, Path(tmp), 4.0)
        for probe, n, method in PROBES:
            t0 = time.perf_counter()
            out = subprocess.run([sys.executable, "-c", CHILD, str(ROOT), probe, str(n), method, str(camp)],
                                 capture_output=True, text=True)
            line = [x for x in out.stdout.splitlines() if x.startswith("RECORD ")]
            rec = json.loads(line[-1][7:]) if line else {"probe": probe, "iterations": n, "chain_method": method,
                                                          "error": out.stderr.strip()[-300:]}
            rec["wall_s"] = round(time.perf_counter() - t0, 1)
            rows.append(rec)
            print(json.dumps(rec), flush=True)
    RECORDS.parent.mkdir(parents=True, exist_ok=True)
    RECORDS.write_text(json.dumps({"date": time.strftime("%Y-%m-%d"), "campaign": "cold_start reference, 18 pairs, "
                                   "4 Hz", "rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
