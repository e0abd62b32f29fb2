"""How far the anemometer's own dynamics move K_D once gusts identify it, and whether
inverting the vane's second-order response on the reading brings it back.

Campaigns of the independent simulator (3 pairs, no Type B errors, no run-to-run spread,
its instrument noise) with the turbulence that identifies K_D, fitted by joint least squares
(``four_term``, one group; the estimate the posterior centres on):

* ``turbulence``: the gusts alone (the baseline: what K_D's error is without the instrument);
* ``+ anemometer``: the gusts and the simulator's anemometer dynamics (cup first order with
  over-speeding, its distance constant stated in vehicle.toml so the ``anemometer_lag`` term
  undoes the first-order part; vane second order, damping 0.3-0.6, undamped wavelength
  4.5-7 m, not stated);
* ``+ anemometer, vane inverted``: the same campaign with the yaw reading replaced by
  psi_m + (2 zeta / omega) dpsi_m/dt + (1 / omega^2) d^2psi_m/dt^2, omega = 2 pi a_m / lambda
  (the vane's equation solved for its input, with the simulator's own zeta and lambda and
  central differences on the sample grid): what a vane correction stated in vehicle.toml
  could at best give at this logging rate;
* ``+ anemometer, ideal vane``: the anemometer dynamics with a vane of wavelength 0.05 m and
  damping 0.9 (it follows the air): the cup's share.

Same seed, same draws in every arm but the anemometer's (the arms with the anemometer draw
its four parameters, which shifts later draws of that campaign).

    python benchmarks/vane_dynamics.py --out benchmarks/records/vane_dynamics.csv --docs
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import bayes_roadload.simulate.independent.campaign as independent_campaign  # noqa: E402
from bayes_roadload.inference.lsq import fit_lsq  # noqa: E402
from bayes_roadload.simulate.independent import simulate_independent  # noqa: E402
from doc_sections import replace_section  # noqa: E402

QUANTITIES = ("KD", "CD0", "AD", "F50_N")
DOC = ROOT / "docs" / "calibration.md"
MARKS = ("<!-- vane_dynamics:begin -->", "<!-- vane_dynamics:end -->")


def inverted_vane(time_s, yaw_rad, airspeed_mps, damping, wavelength_m):
    """The vane's input from its reading: psi = psi_m + (2 zeta / omega) psi_m' + psi_m'' / omega^2,
    omega = 2 pi a_m / lambda (the simulator's vane equation), derivatives by central differences."""
    omega = 2.0 * np.pi * np.maximum(airspeed_mps, 1.0) / wavelength_m
    d1 = np.gradient(yaw_rad, time_s)
    d2 = np.gradient(d1, time_s)
    return np.clip(yaw_rad + 2.0 * damping / omega * d1 + d2 / omega**2, -1.5, 1.5)


def _campaign(seed, pairs, rate, effects, vane=None):
    """A campaign and the anemometer dynamics it drew (None without them); ``vane`` overrides
    the drawn vane's (damping, wavelength)."""
    drawn = {}
    original = independent_campaign.AnemometerDynamics

    def record(**kw):
        if vane is not None:
            kw["vane_damping"], kw["vane_wavelength_m"] = vane
        drawn["dyn"] = original(**kw)
        return drawn["dyn"]

    independent_campaign.AnemometerDynamics = record
    try:
        campaign = simulate_independent(seed, pairs=pairs, effects=effects, type_b=False, run_to_run_sd=0.0,
                                        sample_rate_hz=rate)
    finally:
        independent_campaign.AnemometerDynamics = original
    return campaign, drawn.get("dyn")


def _errors(campaign, arm: str) -> dict:
    fit = fit_lsq(campaign, "four_term", grouping="all")
    row = {"arm": arm}
    for q in QUANTITIES:
        row[f"{q}_err_pct"] = 100.0 * (fit.weighted_mean[q] / campaign.truth[q] - 1.0)
    row["KD_se_pct"] = 100.0 * fit.weighted_se["KD"] / campaign.truth["KD"]
    return row


def one(seed: int, pairs: int, rate: float) -> list[dict]:
    base = {"seed": seed, "pairs": pairs, "sample_rate_hz": rate}
    rows = []
    gusts, _ = _campaign(seed, pairs, rate, ["turbulence"])
    rows.append(_errors(gusts, "turbulence"))
    campaign, dyn = _campaign(seed, pairs, rate, ["turbulence", "anemometer_dynamics"])
    rows.append(_errors(campaign, "+ anemometer"))
    runs = campaign.runs.copy()
    for _, g in runs.groupby("run"):
        runs.loc[g.index, "yaw_rad"] = inverted_vane(g["time_s"].to_numpy(), g["yaw_rad"].to_numpy(),
                                                     g["airspeed_mps"].to_numpy(), dyn.vane_damping,
                                                     dyn.vane_wavelength_m)
    rows.append(_errors(dataclasses.replace(campaign, runs=runs), "+ anemometer, vane inverted"))
    ideal, _ = _campaign(seed, pairs, rate, ["turbulence", "anemometer_dynamics"], vane=(0.9, 0.05))
    rows.append(_errors(ideal, "+ anemometer, ideal vane"))
    meta = {"vehicle": campaign.truth["meta"]["vehicle_true"]["category"], "vane_damping": dyn.vane_damping,
            "vane_wavelength_m": dyn.vane_wavelength_m, "cup_distance_constant_m": dyn.distance_constant_m,
            "cup_overspeed_ratio": dyn.overspeed_ratio}
    return [{**base, **meta, **r} for r in rows]


def markdown(df: pd.DataFrame) -> str:
    """K_D's least-squares error (%) per arm, seed by seed, at each logging rate."""
    lines = ["| rate (Hz) | arm | K_D error (%), seeds " + ", ".join(str(s) for s in sorted(df.seed.unique()))
             + " | K_D standard error (%) |", "|---|---|---|---|"]
    for (rate, arm), g in df.groupby(["sample_rate_hz", "arm"], sort=False):
        g = g.sort_values("seed")
        lines.append(f"| {rate:g} | {arm} | " + " / ".join(f"{x:+.1f}" for x in g["KD_err_pct"])
                     + " | " + " / ".join(f"{x:.1f}" for x in g["KD_se_pct"]) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[0, 1, 300, 301])
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--rates", type=float, nargs="*", default=[10.0, 20.0])
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "records" / "vane_dynamics.csv")
    ap.add_argument("--from-records", action="store_true", help="summarise --out without fitting")
    ap.add_argument("--docs", action="store_true", help="regenerate the table of docs/calibration.md")
    args = ap.parse_args(argv)
    if args.from_records:
        df = pd.read_csv(args.out)
    else:
        rows = []
        for rate in args.rates:
            for seed in args.seeds:
                rows.extend(one(seed, args.pairs, rate))
                args.out.parent.mkdir(parents=True, exist_ok=True)
                pd.DataFrame(rows).to_csv(args.out, index=False)
        df = pd.DataFrame(rows)
    print(markdown(df))
    if args.docs:
        replace_section(DOC, *MARKS, markdown(df))
    shift = df.pivot_table(index=["sample_rate_hz", "seed"], columns="arm", values="KD_err_pct")
    print(json.dumps({"benchmark": "vane_dynamics", "records": str(args.out),
                      "kd_shift_by_anemometer_pct": (shift["+ anemometer"] - shift["turbulence"]).round(2).tolist(),
                      "kd_shift_by_inversion_pct": (shift["+ anemometer, vane inverted"]
                                                    - shift["+ anemometer"]).round(2).tolist()}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
