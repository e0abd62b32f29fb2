"""How much does the reverting residual (``--noise reverting``) change the intervals?

For SBC simulator-arm campaigns (:class:`bayes_roadload.analysis.sbc.PriorDrawnCampaign` with the
random force, 2 pairs; seeds from the command line) fits the SBC model by MAP + Laplace
(:func:`~bayes_roadload.inference.laplace.fit_laplace`, no importance correction, 4000 draws)
with the random-walk residual (``integrated``) and with the reverting one, and prints per
campaign the true q and the ratio reverting / integrated of the posterior sd of AD, BD, CD0, KD,
F50_N and of the MAP's q.

Run::

    python benchmarks/reverting_width.py 0 1 2 4 5 6 > benchmarks/records/sbc/reverting_width.log
"""
import sys

import numpy as np

from bayes_roadload.analysis.sbc import SBC_MODEL, PriorDrawnCampaign
from bayes_roadload.inference.laplace import fit_laplace

for seed in map(int, sys.argv[1:]):
    c = PriorDrawnCampaign(seed, pairs=2, random_force=True)()
    out = {}
    for noise in ("integrated", "reverting"):
        f = fit_laplace(c, SBC_MODEL, noise=noise, importance=False, draws=4000)
        out[noise] = {k: float(np.std(f.samples[k])) for k in ("AD", "BD", "CD0", "KD", "F50_N")}
        out[noise]["q"] = float(f.map.constrained["q_mps_per_sqrt_s"])
    print(seed, round(c.truth["q_mps_per_sqrt_s"], 5),
          {k: round(out["reverting"][k] / out["integrated"][k], 3) for k in out["integrated"]}, flush=True)
