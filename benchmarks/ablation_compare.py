"""An ablation of the independent simulator read beside the study it repeats: the calibration
records of the same seeds with one effect withheld (``calibration_study.py --withhold EFFECT``)
against the records with every effect, quantity by quantity -- intervals that hold the truth,
mean z = (posterior mean - truth) / posterior sd, and the mean z in the gustier and the calmer
half of the campaigns (split at the median of the full study's ``mean_abs_yaw_rad``, so both
record sets use the same halves).  Only seeds that both record sets hold are compared.

    python benchmarks/ablation_compare.py --full docs/calibration/design_seeds3000_3015_admittance.csv \
        --ablated docs/calibration/ablation_cd_yaw_shape_seeds3000_3015.csv --label "no C_D(psi) quartic"
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.batch import record_z  # noqa: E402
from bayes_roadload.analysis.calibration import QUANTITIES  # noqa: E402


def compare(full: pd.DataFrame, ablated: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
    """Per quantity, for both record sets on their common campaigns: held (95 %) of n, mean z,
    mean z in the gustier and the calmer half.  Returns the table and the campaigns used."""
    full = full[full["error"].isna()] if "error" in full else full
    ablated = ablated[ablated["error"].isna()] if "error" in ablated else ablated
    names = sorted(set(full["name"]) & set(ablated["name"]))
    f, a = full.set_index("name").loc[names], ablated.set_index("name").loc[names]
    yaw = f["mean_abs_yaw_rad"]
    gusty = yaw > yaw.median()
    rows = []
    for q in QUANTITIES:
        row = {"quantity": q}
        for label, rec in (("all effects", f), ("ablated", a)):
            z = record_z(rec, q)
            row[f"{label}: held"] = int(rec[f"{q}_in95"].sum())
            row[f"{label}: mean z"] = float(z.mean())
            row[f"{label}: mean z gusty"] = float(z[gusty].mean())
            row[f"{label}: mean z calm"] = float(z[~gusty].mean())
        rows.append(row)
    return pd.DataFrame(rows), names


def markdown(table: pd.DataFrame, n: int, label: str) -> str:
    lines = [f"| quantity | all effects: held of {n}, mean z (gusty / calm half) | {label}: held of {n}, mean z (gusty / calm half) |",
             "| --- | --- | --- |"]
    for _, r in table.iterrows():
        cells = [f"{int(r[f'{k}: held'])}, {r[f'{k}: mean z']:+.2f} ({r[f'{k}: mean z gusty']:+.2f} / "
                 f"{r[f'{k}: mean z calm']:+.2f})" for k in ("all effects", "ablated")]
        lines.append(f"| {r['quantity']} | {cells[0]} | {cells[1]} |")
    held = [int(table[f"{k}: held"].sum()) for k in ("all effects", "ablated")]
    lines.append(f"| all | {held[0]} of {n * len(table)} | {held[1]} of {n * len(table)} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", type=Path, required=True, help="records with every effect")
    ap.add_argument("--ablated", type=Path, nargs="+", required=True, help="records with the effect withheld")
    ap.add_argument("--label", default="ablated")
    args = ap.parse_args(argv)
    ablated = pd.concat([pd.read_csv(p) for p in args.ablated], ignore_index=True)
    table, names = compare(pd.read_csv(args.full), ablated)
    print(f"campaigns {', '.join(names)}\n")
    print(markdown(table, len(names), args.label))
    gates = ablated.set_index("name").loc[names]
    if "gate_pass" in gates:
        first = int((gates["gate_pass"] & (gates.get("retries", 0) == 0)).sum())
        print(f"\n{args.label}: {first} of {len(names)} fits passed every gate first time, "
              f"{int(gates['gate_pass'].sum())} after the retry")
    return 0 if np.isfinite(table.select_dtypes(float).to_numpy()).all() else 1


if __name__ == "__main__":
    sys.exit(main())
