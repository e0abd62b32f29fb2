"""The walk arms' readings in docs/calibration.md, from their records
(``benchmarks/records/sbc/walk_arms/arms_<arm>*.log``, written by ``benchmarks/sbc_walk_arms.py``):
per arm the sd of z over every replicate (each seed once); ``sim`` against ``posthoc`` by the
F-test of their variances; the paired arms against the arm they share seeds with (``sim`` with
``sim_fixed_end`` and ``posthoc_same``, ``exact`` with ``exact_reverting``) by the correlation of
their z and the Pitman-Morgan test of equal variances (the correlation of x + y with x - y).

    python benchmarks/sbc_walk_arms_summary.py > benchmarks/records/sbc/walk_arms/summary.log
"""
import glob
import json
from pathlib import Path

import numpy as np
from scipy import stats

RECORDS = Path(__file__).resolve().parent / "records" / "sbc" / "walk_arms"
ARMS = ("sim", "posthoc", "exact", "exact_clean", "sim_fixed_end", "posthoc_same", "exact_reverting")
QUANTITIES = ("AD", "BD", "CD0", "KD", "At", "Bt")
PAIRED = (("sim", "sim_fixed_end"), ("sim", "posthoc_same"), ("exact", "exact_reverting"))


def load(arm: str) -> dict[int, dict]:
    """Replicate seed -> its z (and q) of one arm, over the arm's record files."""
    files = [RECORDS / f"arms_{arm}.log"] + sorted(Path(p) for p in glob.glob(str(RECORDS / f"arms_{arm}_?.log")))
    out: dict[int, dict] = {}
    for f in files:
        if not f.is_file():
            continue
        for line in f.read_text().splitlines():
            head, _, rest = line.partition(" ")
            if head.isdigit() and rest.startswith("{"):
                out.setdefault(int(head), json.loads(rest))
    return out


arms = {a: load(a) for a in ARMS}
print("sd(z) by arm (replicates)")
for a, z in arms.items():
    print(f"  {a:16s} {len(z):4d}  " + "  ".join(f"{k} {np.std([r[k] for r in z.values()], ddof=1):.2f}"
                                                 for k in QUANTITIES)
          + f"  mean q {np.mean([r['q'] for r in z.values()]):.5f}")
print("sim against posthoc: sd ratio posthoc / sim, F-test of the variances (two-sided)")
for k in QUANTITIES:
    x = np.array([r[k] for r in arms["sim"].values()])
    y = np.array([r[k] for r in arms["posthoc"].values()])
    f = np.var(y, ddof=1) / np.var(x, ddof=1)
    p = 2 * min(stats.f.sf(f, y.size - 1, x.size - 1), stats.f.cdf(f, y.size - 1, x.size - 1))
    print(f"  {k:4s} {np.sqrt(f):.2f}  p = {p:.3f}")
for a, b in PAIRED:
    common = sorted(set(arms[a]) & set(arms[b]))
    print(f"{a} against {b}: {len(common)} paired seeds")
    for k in QUANTITIES:
        x = np.array([arms[a][s][k] for s in common])
        y = np.array([arms[b][s][k] for s in common])
        p = stats.pearsonr(x + y, x - y)[1]
        print(f"  {k:4s} sd {x.std(ddof=1):.2f} / {y.std(ddof=1):.2f}  correlation {np.corrcoef(x, y)[0, 1]:.2f}"
              f"  Pitman-Morgan p = {p:.3f}")
