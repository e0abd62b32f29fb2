"""Named campaigns of the independent simulator refitted by MAP + Laplace: thinned, with a model variant, or an effect withheld.

The calibration study's campaigns (``analysis.calibration.calibration_jobs``: seed, size and
every draw as the study made them) are fitted by MAP and Laplace with the Type B step (the
probe of ``withhold_map_probe.py``, which reproduces NUTS' means and sds on these campaigns to
a few per cent of the sd), either as logged or keeping every ``--keep-every``-th sample of each
run (a 20 Hz log read at 4 Hz: the same physics, instruments and noise per sample), and with
``--model`` (``--model-heavy`` above 3500 kg) instead of the default.  ``--compare`` prints,
seed by seed, the relative errors (%) of two such record files and their paired mean change.

    python benchmarks/seed_refits.py --seeds 9051 9056 9021 9047 9081 9019 9069 9014 9002 9155 \\
        --records benchmarks/records/seed_refits/misses_20hz.csv
    python benchmarks/seed_refits.py --seeds 9051 9056 9021 9047 9081 9019 9069 9014 9002 9155 \\
        --keep-every 5 --records benchmarks/records/seed_refits/misses_20hz_at_4hz.csv
    python benchmarks/seed_refits.py --compare benchmarks/records/seed_refits/misses_20hz.csv \\
        benchmarks/records/seed_refits/misses_20hz_at_4hz.csv
    python benchmarks/seed_refits.py --seeds 9056 9051 --each \\
        --records benchmarks/records/seed_refits/misses_each_effect.csv

    python benchmarks/seed_refits.py --seeds 9051 9056 9019 9069 --realisations 10 \\
        --records benchmarks/records/seed_refits/realisations_one_pair.csv

``--realisations N`` refits realisations 0..N-1 of each campaign (the simulator's
``realisation``: each run's own draws and the gusts anew; the vehicle, site, mean wind,
instruments and Type B errors the seed's) and prints, seed by seed, the spread of the errors
between realisations against the posterior sd: the variance a fit of one campaign cannot see
in its own runs.  ``--each`` refits each campaign once with every effect and once with each effect withheld (the
withheld effect's draws made and discarded: the campaign's pair), and prints the change of the
errors, seed by seed.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import sys
from pathlib import Path

import numpy as np
import pandas as pd

def thinned(campaign, keep_every: int):
    """``campaign`` with every ``keep_every``-th sample of each run kept (the first included)."""
    if keep_every <= 1:
        return campaign
    runs = campaign.runs
    return dataclasses.replace(campaign, runs=runs[runs.groupby("run").cumcount() % keep_every == 0].reset_index(drop=True))


def thinned_factory(factory, keep_every: int):
    """The campaign of ``factory`` (a job's ``campaign_factory``), :func:`thinned`."""
    return thinned(factory(), keep_every)


def run(seeds, keep_every: int = 1, model: str | None = None, model_heavy: str | None = None,
        lo: int = 1, hi: int = 12, workers: int = 2, arms=((),), realisations=(None,),
        effects=None, log=()) -> pd.DataFrame:
    """MAP + Laplace records of the ``seeds``' campaigns (the calibration study's jobs,
    :func:`~bayes_roadload.analysis.calibration.calibration_jobs`, one per seed, arm of
    withheld effects and realisation, their campaigns :func:`thinned`), one row per seed, arm and
    realisation (columns ``keep_every``, ``withheld``, the arm's withheld effects joined by
    spaces, and, for a realisation other than ``None``, ``realisation``); ``effects``: only these
    effects injected (default every one; column ``effects``); ``log``: channels logged beside the
    default ones (column ``logged``)."""
    from bayes_roadload.analysis.batch import batch_client, run_batch
    from bayes_roadload.analysis.calibration import calibration_jobs
    from bayes_roadload.inference.kinds import FitOptions

    options = FitOptions(method="laplace")
    jobs = [dataclasses.replace(job, campaign_factory=functools.partial(thinned_factory, job.campaign_factory, keep_every),
                                tags={**job.tags, "keep_every": keep_every, "withheld": " ".join(arm)})
            for r in realisations for arm in arms
            for job in calibration_jobs(seeds, lo, hi, options=options, model=model, withhold=arm, model_heavy=model_heavy,
                                        realisation=r, effects=effects, log=log)]
    with batch_client(workers=workers) as client:
        return run_batch(jobs, client, progress=False)


EFFECT_SHOWN = ("CD0", "F2_N_per_kph2", "F1_N_per_kph", "KD")
"""The quantities of the ``--each`` tables."""


def error_pct(frame, q: str):
    """The relative error (%) of ``q``'s posterior mean against its truth, row by row."""
    return (frame[f"{q}_mean"] / frame[f"{q}_truth"] - 1.0) * 100.0


def by_effect(records: pd.DataFrame) -> str:
    """Markdown: for each seed (and realisation, when the records have them), the relative error (%) of C_D0, F2, F1 and K_D with every effect
    (the arm withholding none) and the change when each effect is withheld, largest C_D0 change first."""
    shown = EFFECT_SHOWN
    rec = records.assign(withheld=records["withheld"].astype(object).fillna(""))
    lines = []
    per_realisation = "realisation" in rec
    for key, rows in rec.groupby(["seed", "realisation"] if per_realisation else ["seed"]):
        err = pd.DataFrame({q: error_pct(rows, q) for q in shown})
        err.index = rows["withheld"].tolist()
        base = err.loc[""]
        change = (err.drop(index="") - base).sort_values("CD0", ascending=False)
        seed = key[0]
        label = f"seed {seed}" + (f", realisation {int(key[1])}" if per_realisation else "")
        lines += [f"{label} ({int(rows['pairs'].iloc[0])} pairs): every effect " + ", ".join(
                      f"{q} {base[q]:+.2f} %" for q in shown) + "; change when one effect is withheld:", "",
                  "| withheld | " + " | ".join(shown) + " |", "|---" * (1 + len(shown)) + "|"]
        lines += [f"| {name} | " + " | ".join(f"{row[q]:+.2f}" for q in shown) + " |" for name, row in change.iterrows()]
        lines.append("")
    return "\n".join(lines).rstrip()


def by_effect_over_realisations(records: pd.DataFrame) -> str:
    """Markdown: for each seed of ``--each`` records with several realisations, each arm's mean
    relative error (%) of C_D0, F2, F1 and K_D over the realisations and, for each withheld
    effect, the mean paired change against every effect with its standard error (the spread of
    the realisations' changes over the square root of their number), largest C_D0 change first."""
    shown = EFFECT_SHOWN
    rec = records.assign(withheld=records["withheld"].astype(object).fillna(""))
    lines = []
    for seed, rows in rec.groupby("seed"):
        err = pd.DataFrame({q: error_pct(rows, q) for q in shown})
        err[["withheld", "realisation"]] = rows[["withheld", "realisation"]].to_numpy()
        base = err[err["withheld"] == ""].set_index("realisation")[list(shown)]
        n = len(base)
        lines += [f"seed {seed} ({int(rows['pairs'].iloc[0])} pairs, {n} realisations): every effect "
                  + ", ".join(f"{q} {base[q].mean():+.2f} %" for q in shown)
                  + "; mean change (SE) when one effect is withheld, and the arm's mean error:", "",
                  "| withheld | " + " | ".join(shown) + " | CD0 error | F2 error |", "|---" * (3 + len(shown)) + "|"]
        arms = []
        for name, arm in err[err["withheld"] != ""].groupby("withheld"):
            arm = arm.set_index("realisation")[list(shown)]
            change = (arm - base.loc[arm.index]).astype(float)
            se = change.std(ddof=1) / np.sqrt(len(change)) if len(change) > 1 else change.mean() * np.nan
            arms.append((change["CD0"].mean(), name, change.mean(), se, arm.astype(float).mean()))
        for _, name, mean, se, level in sorted(arms, key=lambda a: -a[0]):
            lines.append(f"| {name} | " + " | ".join(f"{mean[q]:+.2f} ({se[q]:.2f})" for q in shown)
                         + f" | {level['CD0']:+.2f} | {level['F2_N_per_kph2']:+.2f} |")
        lines.append("")
    return "\n".join(lines).rstrip()


SPREAD_SHOWN = ("CD0", "F2_N_per_kph2", "F1_N_per_kph", "F0_N", "F50_N", "AD", "KD")


def by_realisation(records: pd.DataFrame) -> str:
    """Markdown: each seed's vehicle category, K_D, turbulence sd (the campaign's draws, which
    its realisations keep) and mean absolute logged yaw over its realisations; then for each
    seed and quantity of :data:`SPREAD_SHOWN`, over its realisations, the
    mean relative error (%; the bias a realisation does not change), the sd of the relative
    errors between realisations (the realisation spread), the mean relative posterior sd and
    their ratio (above 1: the fit does not see how much another day's runs would move it), the
    sd(z), the 95 % intervals holding the truth and the range of the errors; then the same pooled over the seeds (the
    spread as the rms of the seeds' spreads)."""
    from bayes_roadload.simulate.independent import first_draws, simulate_independent

    lines = ["| seed | vehicle | K_D (rad^-2) | turbulence sd (m/s) | mean abs logged yaw (rad) |", "|---" * 5 + "|"]
    for seed, rows in records.groupby("seed"):
        # the campaign's own draws, which every realisation keeps (one pair simulated to read them)
        meta = simulate_independent(int(seed), pairs=1, realisation=0).truth["meta"]
        lines.append(f"| {seed} | {meta['vehicle_true']['category']} | {rows['KD_truth'].iloc[0]:.2f} | "
                     f"{meta['wind']['turbulence_sigma_mps']:.2f} | {rows['mean_abs_yaw_rad'].mean():.3f} |")
    lines += ["", "| seed | pairs | rate Hz | quantity | realisations | mean error % | spread % | posterior sd % "
             "| spread / sd | sd(z) | 95 % hold | error range % |", "|---" * 12 + "|"]
    pooled = {q: [] for q in SPREAD_SHOWN}
    for seed, rows in records.groupby("seed"):
        rate = first_draws(int(seed))[1] / (int(rows["keep_every"].iloc[0]) if "keep_every" in rows else 1)
        for q in SPREAD_SHOWN:
            err = error_pct(rows, q)
            sd = (rows[f"{q}_sd"] / rows[f"{q}_truth"].abs()) * 100.0
            z = (rows[f"{q}_mean"] - rows[f"{q}_truth"]) / rows[f"{q}_sd"]
            held = int(rows[f"{q}_in95"].astype(bool).sum())
            spread = err.std(ddof=1)
            pooled[q].append((len(rows), err.mean(), spread, sd.mean(), z, held))
            lines.append(f"| {seed} | {int(rows['pairs'].iloc[0])} | {rate:g} | {q} | {len(rows)} | {err.mean():+.2f} "
                         f"| {spread:.2f} | {sd.mean():.2f} | {spread / sd.mean():.2f} | {z.std(ddof=1):.2f} "
                         f"| {held} / {len(rows)} | {err.min():+.1f} to {err.max():+.1f} |")
    lines += ["", "| quantity | campaigns | fits | rms mean error % | rms spread % | rms posterior sd % "
              "| spread / sd | sd(z) | 95 % hold |", "|---" * 9 + "|"]
    for q, rows in pooled.items():
        n = sum(r[0] for r in rows)
        rms = [float(np.sqrt(np.mean([r[i] ** 2 for r in rows]))) for i in (1, 2, 3)]
        z = pd.concat([r[4] for r in rows])
        lines.append(f"| {q} | {len(rows)} | {n} | {rms[0]:.2f} | {rms[1]:.2f} | {rms[2]:.2f} | {rms[1] / rms[2]:.2f} "
                     f"| {z.std(ddof=1):.2f} | {sum(r[5] for r in rows)} / {n} |")
    return "\n".join(lines)


def compare(first: pd.DataFrame, second: pd.DataFrame) -> str:
    """Markdown: each common seed's relative error (%) of C_D0, K_D, F1, F2 in both record files
    and C_D0's relative posterior sd, then the mean of each column and the paired mean change
    (second - first) with its standard error."""
    a, b = first.set_index("seed"), second.set_index("seed")
    common = a.index.intersection(b.index)
    shown = ("CD0", "KD", "F1_N_per_kph", "F2_N_per_kph2")
    err = {(q, k): error_pct(f.loc[common], q) for q in shown for k, f in (("first", a), ("second", b))}
    sd = {k: f.loc[common, "CD0_sd"] / f.loc[common, "CD0_truth"] * 100.0 for k, f in (("first", a), ("second", b))}
    lines = [f"{len(common)} campaigns; relative error %, first / second record file", "",
             "| seed | pairs | " + " | ".join(shown) + " | C_D0 sd % |", "|---" * (3 + len(shown)) + "|"]
    for s in common:
        cells = [f"{err[(q, 'first')][s]:+.2f} / {err[(q, 'second')][s]:+.2f}" for q in shown]
        lines.append(f"| {s} | {int(a.loc[s, 'pairs'])} | " + " | ".join(cells)
                     + f" | {sd['first'][s]:.2f} / {sd['second'][s]:.2f} |")
    cells = [f"{err[(q, 'first')].mean():+.2f} / {err[(q, 'second')].mean():+.2f}" for q in shown]
    lines.append("| mean | | " + " | ".join(cells) + f" | {sd['first'].mean():.2f} / {sd['second'].mean():.2f} |")
    changes = []
    for q in shown:
        d = err[(q, "second")] - err[(q, "first")]
        se = d.std(ddof=1) / np.sqrt(len(d)) if len(d) > 1 else float("nan")
        changes.append(f"{d.mean():+.2f} ({se:.2f})")
    lines.append("| paired change (SE) | | " + " | ".join(changes) + " | |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", help="the campaigns (calibration study seeds)")
    ap.add_argument("--pairs", type=int, nargs=2, default=(1, 12), metavar=("MIN", "MAX"))
    ap.add_argument("--keep-every", type=int, default=1, help="keep every k-th sample of each run (default 1: all)")
    ap.add_argument("--model", default=None, help="the analysis model (default: fit's default)")
    ap.add_argument("--model-heavy", default=None, help="with --model: the model above 3500 kg test mass")
    ap.add_argument("--each", nargs="*", metavar="EFFECT",
                    help="one arm with every effect and one per named effect withheld (no names: every effect)")
    ap.add_argument("--realisations", type=int, default=0, metavar="N",
                    help="fit realisations 0..N-1 of each campaign (each run's draws and the gusts anew, the "
                         "campaign's draws kept) and print their spread against the posterior sd")
    ap.add_argument("--effects", nargs="*", metavar="EFFECT",
                    help="inject only these effects (no names: none; default every one)")
    ap.add_argument("--log", nargs="+", default=(), metavar="CHANNEL",
                    help="channels logged beside the default ones (e.g. survey: the track's level survey)")
    ap.add_argument("--workers", type=int, default=2, help="Dask workers")
    ap.add_argument("--records", type=Path, help="write the records here (CSV)")
    ap.add_argument("--compare", type=Path, nargs=2, metavar=("FIRST", "SECOND"), help="only compare two record files")
    ap.add_argument("--from-records", type=Path,
                    help="only print the table of records written before (--each: per realisation, or with "
                         "--realisations N > 1 their mean change; else the spread between realisations)")
    a = ap.parse_args(argv)
    if a.compare:
        print(compare(*(pd.read_csv(p) for p in a.compare)))
        return 0
    if a.from_records:
        records = pd.read_csv(a.from_records)
        if "withheld" in records and records["withheld"].notna().any():
            print(by_effect_over_realisations(records) if a.realisations > 1 else by_effect(records))
        else:
            print(by_realisation(records))
        return 0
    if not a.seeds:
        ap.error("give --seeds, --compare or --from-records")
    arms = ((),)
    if a.each is not None:
        from bayes_roadload.simulate.independent import EFFECTS

        arms = ((),) + tuple((e,) for e in (a.each or EFFECTS))
    realisations = tuple(range(a.realisations)) if a.realisations else (None,)
    records = run(a.seeds, a.keep_every, a.model, a.model_heavy, *a.pairs, workers=a.workers, arms=arms,
                  realisations=realisations, effects=a.effects, log=a.log)
    if a.records:
        a.records.parent.mkdir(parents=True, exist_ok=True)
        records.to_csv(a.records, index=False)
    if a.each is not None:
        print(by_effect_over_realisations(records) if a.realisations > 1 else by_effect(records))
        return 0
    if a.realisations:
        print(by_realisation(records))
        return 0
    print(records[["seed", "pairs", "keep_every", "n_samples"]
                  + [f"{q}_{c}" for q in ("CD0", "KD") for c in ("mean", "truth", "sd")]].to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
