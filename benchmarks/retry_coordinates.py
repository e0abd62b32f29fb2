"""The retry after divergences in the direct coordinates: the campaigns whose tyre-lag fits
diverged in the apparent coefficients, refitted with the current retry.

:func:`bayes_roadload.inference.nuts.sample_problem` retries a fit whose first attempt diverged
in the alternative coordinates of its problem (``Problem.alternative_coordinates``: for the
tyre-lag model, A_D, B_D, C_D0 sampled directly instead of the apparent coefficients), with
the remedy's sampler (target acceptance 0.99, twice the warm-up and draws).  The campaigns:

* the exact-SBC campaigns of ``four_term_tyre_lag_driveline_informative`` whose first attempt
  diverged (seeds 5, 20, 44 of ``benchmarks/records/sbc/lag_exact_part1*.csv``; 2 pairs);
* thesis cases 14 and 15 at one pair, seed 0, ``four_term_tyre_lag`` (the two divergence
  retries of ``benchmarks/records/gates/gate_rate_tyre_lag_apparent_cd0_one_pair.csv``);
* the eco-car GNSS traces, each pair alone, ``four_term_tyre_lag`` (both failed their gates
  after the retry in the apparent coefficients: docs/calibration.md, real data), when
  ``../shared/data/external`` is present.

Fits run one after the other in this process (the eco-car campaign is read here).  Writes the
records (CSV, the batch door's columns) and prints one line per fit: first-attempt failure,
the retry's coordinates, whether the kept draws pass every gate, their divergences.

Run (record ``benchmarks/records/gates/retry_coordinates.csv``)::

    python benchmarks/retry_coordinates.py --records benchmarks/records/gates/retry_coordinates.csv
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bayes_roadload.analysis.batch import FitJob, SimulatedCampaign, run_batch  # noqa: E402
from bayes_roadload.analysis.sbc import ModelDrawnCampaign  # noqa: E402

LAG = "four_term_tyre_lag"
LAG_SBC = "four_term_tyre_lag_driveline_informative"
SBC_SEEDS = (5, 20, 44)
THESIS_CASES = (14, 15)


@dataclass(frozen=True)
class GnssPair:
    """One opposite-direction pair of the eco-car GNSS traces (``real_data.gnss_campaign``)."""

    pair: int

    def __call__(self):
        from real_data import GNSS_RUNS, gnss_campaign

        return gnss_campaign().subset([name for name, _, pair in GNSS_RUNS if pair == self.pair])


def jobs(with_gnss: bool) -> list[FitJob]:
    out = [FitJob(f"sbc-lag-{s}", ModelDrawnCampaign(s, pairs=2, model=LAG_SBC), model=LAG_SBC,
                  tags={"source": "exact SBC", "case": s, "pairs": 2}) for s in SBC_SEEDS]
    out += [FitJob(f"case{c}-p1-s0", SimulatedCampaign(c, 1, 0), model=LAG,
                   tags={"source": "thesis case", "case": c, "pairs": 1}) for c in THESIS_CASES]
    if with_gnss:
        out += [FitJob(f"gnss-pair{p}", GnssPair(p), model=LAG, type_b=False,
                       tags={"source": "eco-car GNSS", "case": p, "pairs": 1}) for p in (1, 2)]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=Path, required=True)
    ap.add_argument("--no-gnss", action="store_true", help="leave out the eco-car traces")
    args = ap.parse_args(argv)
    from real_data import GNSS_DIR

    with_gnss = not args.no_gnss and Path(GNSS_DIR).is_dir()
    records = run_batch(jobs(with_gnss), None)
    args.records.parent.mkdir(parents=True, exist_ok=True)
    records.to_csv(args.records, index=False)
    print(summary(records))
    return 0


def summary(records: pd.DataFrame) -> str:
    cols = ["name", "retry_failed", "retry_coordinates", "gate_pass", "gates_failed", "divergences"]
    have = [c for c in cols if c in records]
    return records[have].to_string(index=False)


if __name__ == "__main__":
    sys.exit(main())
