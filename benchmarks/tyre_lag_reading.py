"""The calibration study's C_D0 and F2 errors against the tyre-lag gain: fitted and the simulator's own.

Reads the records of a calibration run (``benchmarks/calibration_study.py``), rebuilds each
campaign's true vehicle (the independent simulator's first draw of a seed whose campaign size is
given, checked against the records' true C_D0), and prints, as markdown:

* the mean z and 95 % coverage of C_D0 and F2 by the quartile of the fitted tyre-lag gain G_T
  (posterior mean), of the simulator's own G = k r (its tyre temperature coefficient times its
  steady temperature rise per m/s) and of its tyre time constant (the analysis holds 400 +- 200 s);
* the same by the simulator's yaw-drag quartic K4 (its levelling at large yaw) and by the
  campaign's logging rate (the simulator's draw after the vehicle);
* the same by the simulator's vehicle category, and by category and the calm / gusty half of
  the campaigns' mean absolute yaw;
* how well the fit recovers G: the correlation of the fitted with the true value, the gain's own
  95 % coverage and sd(z) against G, and the correlation of its error with C_D0's and F2's z.

A reading of a run already made, not a rule.

    python benchmarks/tyre_lag_reading.py docs/calibration/humidity_budget_records.partial.csv \
        > benchmarks/records/tyre_lag_reading_seeds9000.txt
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd

from bayes_roadload.simulate.independent import first_draws

GAIN = "tyre_lag_gain_per_mps"


def with_true_tyres(records: pd.DataFrame) -> pd.DataFrame:
    """``records`` with the simulator's true ``G_true`` (= k r), ``tau_true_s`` and the z of
    C_D0, F2 and G_T and the relative error (%) of C_D0 and F2; refuses records whose
    rebuilt vehicle is not the one fitted."""
    rows = []
    for seed in records["seed"]:
        v, rate = first_draws(int(seed))
        rows.append({"seed": seed, "cd0": v.cd0, "category": v.category, "k4_per_rad4": v.k4_per_rad4,
                     "sample_rate_hz": rate, "G_true": v.tyre_temp_coeff_per_k * v.tyre_rise_k_per_mps,
                     "tau_true_s": v.tyre_tau_s})
    out = records.merge(pd.DataFrame(rows), on="seed")
    if not np.allclose(out["cd0"], out["CD0_truth"], rtol=1e-12):
        raise SystemExit("the rebuilt vehicles are not the records' (the simulator's draw order changed)")
    for q in ("CD0", "F2_N_per_kph2"):
        out[f"z_{q}"] = (out[f"{q}_mean"] - out[f"{q}_truth"]) / out[f"{q}_sd"]
        out[f"err_{q}"] = (out[f"{q}_mean"] / out[f"{q}_truth"] - 1.0) * 100.0
    out["z_G"] = (out[f"{GAIN}_mean"] - out["G_true"]) / out[f"{GAIN}_sd"]
    return out


def by_quartile(rec: pd.DataFrame, column: str, label: str) -> list[str]:
    """Markdown rows: n, C_D0's and F2's coverage and mean z by the quartile of ``column``."""
    bins = pd.qcut(rec[column], 4)
    lines = [f"| {label} | n | C_D0 coverage | C_D0 mean z | F2 coverage | F2 mean z |", "|---|---|---|---|---|---|"]
    for b, part in rec.groupby(bins, observed=True):
        lines.append(f"| {b.left:.4g} to {b.right:.4g} | {len(part)} | {part['CD0_in95'].mean():.2f} | "
                     f"{part['z_CD0'].mean():+.2f} | {part['F2_N_per_kph2_in95'].mean():.2f} | "
                     f"{part['z_F2_N_per_kph2'].mean():+.2f} |")
    return lines


def by_category(rec: pd.DataFrame) -> list[str]:
    """Markdown rows: n, C_D0's and F2's coverage, mean z and mean relative error (%) by the
    simulator's vehicle category, and by category and the half of mean absolute yaw (split at
    the median of all campaigns)."""
    rec = rec.assign(yaw_half=np.where(rec["mean_abs_yaw_rad"] > rec["mean_abs_yaw_rad"].median(), "gusty", "calm"))
    lines = ["| vehicle category (yaw half) | n | C_D0 coverage | C_D0 mean z | C_D0 mean error % | F2 coverage | "
             "F2 mean z | F2 mean error % |", "|---|---|---|---|---|---|---|---|"]
    for keys in (["category"], ["category", "yaw_half"]):
        for name, part in rec.groupby(keys):
            label = " ".join(name) if isinstance(name, tuple) else name
            lines.append(f"| {label} | {len(part)} | {part['CD0_in95'].mean():.2f} | {part['z_CD0'].mean():+.2f} | "
                         f"{part['err_CD0'].mean():+.2f} | {part['F2_N_per_kph2_in95'].mean():.2f} | "
                         f"{part['z_F2_N_per_kph2'].mean():+.2f} | {part['err_F2_N_per_kph2'].mean():+.2f} |")
    return lines


def by_rate(rec: pd.DataFrame) -> list[str]:
    """Markdown rows by the campaign's logging rate: n, mean pairs, C_D0's coverage, mean z,
    mean and rms relative error (%) and median relative posterior sd (%), F2's coverage and mean z."""
    rsd = rec["CD0_sd"] / rec["CD0_truth"] * 100.0
    lines = ["| logging rate (Hz) | n | mean pairs | C_D0 coverage | C_D0 mean z | C_D0 mean error % | C_D0 rms error % | "
             "C_D0 median sd % | F2 coverage | F2 mean z |", "|---|---|---|---|---|---|---|---|---|---|"]
    for rate, part in rec.groupby("sample_rate_hz"):
        e = part["err_CD0"]
        lines.append(f"| {rate:g} | {len(part)} | {part['pairs'].mean():.1f} | {part['CD0_in95'].mean():.2f} | "
                     f"{part['z_CD0'].mean():+.2f} | {e.mean():+.2f} | {np.sqrt(np.mean(e**2)):.2f} | "
                     f"{rsd[part.index].median():.2f} | {part['F2_N_per_kph2_in95'].mean():.2f} | "
                     f"{part['z_F2_N_per_kph2'].mean():+.2f} |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("records", help="a calibration study's records (CSV)")
    args = ap.parse_args(argv)
    records = pd.read_csv(args.records)
    if "error" in records:
        records = records[records["error"].isna()]
    rec = with_true_tyres(records.reset_index(drop=True))
    err = rec[f"{GAIN}_mean"] - rec["G_true"]
    lines = [f"{len(rec)} campaigns of `{args.records}`.", "",
             f"Fitted G_T against the simulator's G = k r: correlation {rec[f'{GAIN}_mean'].corr(rec['G_true']):.2f}; "
             f"95 % coverage {float((rec['z_G'].abs() <= 1.96).mean()):.2f}, mean z {rec['z_G'].mean():+.2f}, "
             f"sd(z) {rec['z_G'].std():.2f}; correlation of its error with C_D0's z {err.corr(rec['z_CD0']):+.2f}, "
             f"with F2's z {err.corr(rec['z_F2_N_per_kph2']):+.2f}; G over the campaigns "
             f"{rec['G_true'].min():.4f}-{rec['G_true'].max():.4f} (mean {rec['G_true'].mean():.4f}).", ""]
    lines += by_quartile(rec, f"{GAIN}_mean", "fitted G_T (1/(m/s))") + [""]
    lines += by_quartile(rec, "G_true", "simulator's G = k r (1/(m/s))") + [""]
    lines += by_quartile(rec, "tau_true_s", "simulator's tyre time constant (s)") + [""]
    lines += by_quartile(rec.assign(yaw_deg=np.degrees(rec["mean_abs_yaw_rad"])), "yaw_deg", "mean abs. yaw (deg)") + [""]
    lines += by_category(rec) + [""]
    lines += by_quartile(rec, "k4_per_rad4", "simulator's yaw-drag quartic K4 (rad^-4; more negative: more levelling)") + [""]
    lines += by_rate(rec)
    sys.stdout.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
