"""Which properties of a campaign go with the default's interval misses on the independent simulator.

For every record of a calibration run (``benchmarks/calibration_study.py``), the campaign is
simulated again from its seed and size (``simulate_independent(seed, pairs=P)``: the same draws,
so the same vehicle, Type B errors and wind), and its z-scores (posterior mean minus truth, over
the posterior sd) are set beside what the simulator drew: the vehicle (``meta.vehicle_true``),
the declared values' errors (``meta.type_b_errors``), the air's humidity, the wind and the
logging rate.  No fit is
run: the records' posteriors are read as they are.

Writes one row per campaign (``--out``, CSV: seed, pairs, the z of each quantity, the drawn
properties) and prints, for each quantity, the properties whose Pearson correlation with its z is
largest in magnitude, with the approximate two-sided 5 % bound for no correlation,
2 / sqrt(n).  A correlation is a pointer to a cause, to be checked by an ablation
(``benchmarks/admittance_ablation.py`` is one), not a finding on its own.

    python benchmarks/coverage_attribution.py docs/calibration/independent_records.csv \\
        docs/calibration/design_seeds3000_3015_admittance.csv --out docs/calibration/attribution.csv
    python benchmarks/coverage_attribution.py --from-table docs/calibration/attribution.csv
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_roadload.analysis.batch import record_z  # noqa: E402
from bayes_roadload.analysis.calibration import QUANTITIES  # noqa: E402
from bayes_roadload.physics.atmosphere import air_density_kgpm3  # noqa: E402
from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402
from bayes_roadload.simulate.independent.dynamics import moist_air_density  # noqa: E402

TYPE_B = ("mass_kg", "rotating_inertia_rel", "airspeed_factor_rel", "yaw_factor_rel", "yaw_offset_rad",
          "speed_scale_rel", "temperature_bias_k", "pressure_bias_pa", "track_mean_grade")
"""The declared values' errors of ``meta.type_b_errors`` set beside the z-scores."""


def drawn_properties(seed: int, pairs: int, truth: dict[str, float]) -> dict[str, float]:
    """What the independent simulator drew for ``seed`` at ``pairs`` pairs, checked to be the
    record's campaign (its true A_D, B_D, C_D0, K_D equal ``truth``'s): the numeric fields of
    the true vehicle (``veh_*``, with ``veh_k4_over_kd`` the yaw drag's levelling relative to its
    curvature), the declared values' errors (``err_*``), the mean wind (``wind_*``) and the
    logging rate."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        camp = simulate_independent(seed, pairs=pairs)
    for q in ("AD", "BD", "CD0", "KD"):
        if not math.isclose(float(camp.truth[q]), truth[q], rel_tol=1e-9):
            raise RuntimeError(f"seed {seed}: the simulated {q} {camp.truth[q]} is not the record's {truth[q]}")
    meta = camp.truth["meta"]
    veh = {f"veh_{k}": float(v) for k, v in meta["vehicle_true"].items() if isinstance(v, (int, float))}
    veh["veh_k4_over_kd"] = veh["veh_k4_per_rad4"] / veh["veh_kd_per_rad2"]
    err = {f"err_{k}": float(meta["type_b_errors"][k]) for k in TYPE_B}
    err["err_mass_rel"] = err.pop("err_mass_kg") / veh["veh_mass_kg"]
    wind = meta["wind"]
    t0, p0, rh = float(meta["temperature0_k"]), float(meta["pressure0_pa"]), float(meta["relative_humidity"])
    air = {"air_relative_humidity": rh,
           # the analysis takes dry air at the logged temperature and pressure: its density's error
           "air_density_dry_over_moist_rel": float(air_density_kgpm3(p0, t0) / moist_air_density(p0, t0, rh)) - 1.0}
    return {**veh, **err, **air, "wind_mean_speed_mps": float(wind["mean_speed_mps"]),
            "wind_turbulence_sigma_mps": float(wind["turbulence_sigma_mps"]),
            "sample_rate_hz": float(meta["sample_rate_hz"])}


def z_scores(records: pd.DataFrame) -> pd.DataFrame:
    """(mean - truth) / sd of each quantity of :data:`QUANTITIES` the records hold."""
    return pd.DataFrame({q: record_z(records, q) for q in QUANTITIES if f"{q}_mean" in records})


DRY_AIR_QUANTITIES = ("CD0", "KD")
"""Coefficients proportional to the dynamic pressure, which the dry-air density overstates."""


def dry_air_z(table: pd.DataFrame, records: pd.DataFrame) -> pd.DataFrame:
    """The z each campaign's C_D0 and K_D would have from the dry-air density's error alone
    (``{q}_z_dry_air``): with the density too large by the factor 1 + e
    (``air_density_dry_over_moist_rel``), a coefficient of the dynamic pressure reads low by
    e / (1 + e) of its truth, i.e. z = -(e / (1 + e)) truth / sd with the record's sd."""
    cols = [f"{q}_{k}" for q in DRY_AIR_QUANTITIES for k in ("truth", "sd")]
    m = table[["seed"]].merge(records[["seed", *cols]], on="seed", how="left")
    e = table["air_density_dry_over_moist_rel"].to_numpy()
    out = table.copy()
    for q in DRY_AIR_QUANTITIES:
        out[f"{q}_z_dry_air"] = -(e / (1.0 + e)) * (m[f"{q}_truth"] / m[f"{q}_sd"]).to_numpy()
    return out


def correlations(table: pd.DataFrame, quantities: list[str], top: int) -> pd.DataFrame:
    """The ``top`` properties by |Pearson r| with each quantity's z (constant columns skipped)."""
    props = [c for c in table.columns if c.startswith(("veh_", "err_", "air_", "wind_", "sample_rate", "mean_abs_yaw"))
             and table[c].nunique() > 1]
    rows = []
    for q in quantities:
        r = {p: float(np.corrcoef(table[p].astype(float), table[q])[0, 1]) for p in props}
        for p in sorted(r, key=lambda k: -abs(r[k]))[:top]:
            rows.append({"quantity": q, "property": p, "r": round(r[p], 3)})
    return pd.DataFrame(rows)


def halves(table: pd.DataFrame, quantities: list[str], props: list[str]) -> pd.DataFrame:
    """Mean z of each quantity in the campaigns above and at or below the median of each
    property (a reading less sensitive to one extreme campaign than Pearson's r)."""
    rows = []
    for q in quantities:
        for p in props:
            above = table[p] > table[p].median()
            rows.append({"quantity": q, "property": p, "n_above": int(above.sum()),
                         "mean_z_above": round(float(table.loc[above, q].mean()), 2),
                         "mean_z_below": round(float(table.loc[~above, q].mean()), 2)})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("records", nargs="*", type=Path, help="calibration records (CSV) of the independent simulator")
    ap.add_argument("--out", type=Path, help="CSV of z-scores beside the drawn properties")
    ap.add_argument("--from-table", type=Path, help="read a table --out wrote instead of simulating again "
                                                     "(with records: the dry-air columns added from them)")
    ap.add_argument("--top", type=int, default=5, help="properties printed per quantity")
    args = ap.parse_args(argv)
    records = None
    if args.records:
        records = pd.concat([pd.read_csv(p) for p in args.records], ignore_index=True).drop_duplicates("seed")
        records = records[records["error"].isna()] if "error" in records else records
    if args.from_table:
        table = pd.read_csv(args.from_table)
    else:
        if records is None or not args.out:
            ap.error("records and --out are needed unless --from-table is given")
        drawn = pd.DataFrame([drawn_properties(int(r["seed"]), int(r["pairs"]), {q: float(r[f"{q}_truth"]) for q in
                                                                                  ("AD", "BD", "CD0", "KD")})
                              for _, r in records.iterrows()])
        table = pd.concat([records[["seed", "pairs", "mean_abs_yaw_rad"]].reset_index(drop=True),
                           z_scores(records).reset_index(drop=True), drawn], axis=1)
    if records is not None and "air_density_dry_over_moist_rel" in table:
        table = dry_air_z(table, records)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.out, index=False)
    z = table[[q for q in QUANTITIES if q in table]]
    n = len(table)
    print(f"{n} campaigns; |r| above {2 / math.sqrt(n):.2f} is outside the 5 % band of no correlation")
    print("mean z: " + ", ".join(f"{q} {table[q].mean():+.2f}" for q in z.columns))
    top = correlations(table, list(z.columns), args.top)
    print(top.to_string(index=False))
    for q in DRY_AIR_QUANTITIES:
        if f"{q}_z_dry_air" in table:
            dry = table[f"{q}_z_dry_air"]
            print(f"{q}: mean z {table[q].mean():+.2f}, of which the dry-air density's error (the air's humidity) "
                  f"{dry.mean():+.2f} (r with z {np.corrcoef(dry, table[q])[0, 1]:+.2f}); mean z without it "
                  f"{(table[q] - dry).mean():+.2f}")
    print("\nmean z above / at or below each property's median:")
    print(halves(table, list(z.columns), ["veh_k4_over_kd", "veh_k4_per_rad4", "mean_abs_yaw_rad",
                                          "wind_turbulence_sigma_mps"]).to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
