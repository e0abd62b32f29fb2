"""How much drag the anemometer's readings add over the air the body feels, on the independent simulator.

For each seed, the independent simulator's campaign as the calibration study draws it (every
effect on) is simulated again and each run's true states are kept: the relative air the body
feels, the true air at the anemometer and the cup's and vane's states.  The aerodynamic force
``V^2 (C_D0 + K_D psi^2)`` (the vehicle's true C_D0 and K_D) is averaged over the run's samples
three ways and set against the body's:

* ``air``: the true air at the anemometer through the analysis' admittance filter
  (:func:`bayes_roadload.physics.admittance.felt_air`): what the analysis would read with a
  perfect instrument at that point;
* ``cup_lag_corrected``: the cup's and vane's states (before calibration factors and noise),
  the cup's first-order lag taken out as the analysis takes it when ``[anemometer]
  distance_constant_m`` is stated (``a + (d / a) da/dt``, the term ``anemometer_lag``, the
  rate from the logged samples), then the admittance filter;
* ``cup_raw``: the same without the lag correction.

What is left in ``cup_lag_corrected`` against ``air`` is the cup's over-speeding (it spins up
faster than it slows down, ``AnemometerDynamics.overspeed_ratio``) and the vane's dynamics,
which the analysis does not model: a reading of the drag that is too high by that much makes a
fit read C_D0 low by about as much.  The split by speed (below 15 m/s and above 20 m/s) shows its
shape: a bias growing as the airspeed falls reads as less v^2 load and more linear load.

With ``--records`` of a calibration run, prints the campaigns' C_D0, F2 and F1 z against the
bias.  Simulation only, no fit.

    python benchmarks/cup_overspeeding.py --seeds 9000 9039 \\
        --out benchmarks/records/cup_overspeeding_seeds9000_9039.csv \\
        --records docs/calibration/humidity_budget_records.partial.csv
    python benchmarks/cup_overspeeding.py --from-records benchmarks/records/cup_overspeeding_seeds3000_3015.csv \\
        --probe benchmarks/records/withhold_map/anemometer_yaw_factor_withheld_seeds3000_3015.csv \\
        benchmarks/records/withhold_map/anemometer_dynamics_withheld_paired_seeds3000_3015.csv
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

LOW_SPEED_MPS = 15.0
HIGH_SPEED_MPS = 20.0
WAYS = ("air", "cup_lag_corrected", "cup_raw")


def run_records(seed: int) -> list[dict]:
    """One row per run of seed's campaign: the relative bias (%) of the mean aerodynamic force
    read each of :data:`WAYS` against the body's, over the run and its low- and high-speed parts."""
    import bayes_roadload.simulate.independent.campaign as campaign
    from bayes_roadload.analysis.calibration import pairs_of
    from bayes_roadload.physics.admittance import felt_air

    runs = []
    simulate_run = campaign.simulate_run

    def keeping(veh, cond, samples, **kw):
        trace = simulate_run(veh, cond, samples, **kw)
        runs.append((veh, kw.get("anemometer"), trace))
        return trace

    pairs = pairs_of(seed, 1, 12)
    campaign.simulate_run = keeping
    try:
        campaign.simulate_independent(seed, pairs=pairs)
    finally:
        campaign.simulate_run = simulate_run
    rows = []
    for k, (veh, dyn, tr) in enumerate(runs[-2 * pairs:]):  # the campaign's runs (an earlier integration sizes the track)
        t = tr.time_s
        body = tr.airspeed_mps**2 * (veh.cd0 + veh.kd_per_rad2 * tr.yaw_rad**2)
        lagged = tr.cup_mps + (dyn.distance_constant_m / tr.cup_mps * np.gradient(tr.cup_mps, t) if dyn else 0.0)
        low, high = tr.speed_mps < LOW_SPEED_MPS, tr.speed_mps > HIGH_SPEED_MPS
        row = {"seed": seed, "run": k + 1, "category": veh.category, "kd_per_rad2": veh.kd_per_rad2,
               "length_m": veh.length_m, "sample_rate_hz": 1.0 / float(np.median(np.diff(t))),
               "rms_yaw_deg": float(np.degrees(np.sqrt(np.mean(tr.yaw_rad**2)))),
               "overspeed_ratio": dyn.overspeed_ratio if dyn else np.nan,
               "distance_constant_m": dyn.distance_constant_m if dyn else np.nan}
        for way, (a, y) in zip(WAYS, ((tr.anem_airspeed_mps, tr.anem_yaw_rad), (lagged, tr.vane_rad),
                                      (tr.cup_mps, tr.vane_rad))):
            va, psi = (np.asarray(x) for x in felt_air(t, tr.speed_mps, a, y, veh.length_m))
            read = va**2 * (veh.cd0 + veh.kd_per_rad2 * psi**2)
            row[f"{way}_pct"] = (read.mean() / body.mean() - 1.0) * 100.0
            row[f"{way}_low_pct"] = (read[low].mean() / body[low].mean() - 1.0) * 100.0 if low.any() else np.nan
            row[f"{way}_high_pct"] = (read[high].mean() / body[high].mean() - 1.0) * 100.0 if high.any() else np.nan
        rows.append(row)
    return rows


def simulate(seeds, workers: int) -> pd.DataFrame:
    """Rows of every seed, on a Dask ``LocalCluster`` of ``workers`` (0: in this process)."""
    from bayes_roadload.analysis.batch import batch_client, batch_map

    seeds = [int(s) for s in seeds]
    if workers:
        with batch_client(workers=workers) as client:
            out = batch_map(run_records, seeds, client, desc="campaigns")
    else:
        out = [run_records(s) for s in seeds]
    return pd.DataFrame([row for rows in out for row in rows])


def summary(rows: pd.DataFrame, records: pd.DataFrame | None = None,
            probe: tuple[pd.DataFrame, pd.DataFrame] | None = None) -> str:
    """Markdown: the mean bias of each way by vehicle category and by the run's rms yaw; with
    calibration ``records``, the campaigns' z against their cup bias; with ``probe`` (the first
    and second arm's MAP records of ``withhold_map_probe.py``, one row per seed), each seed's
    paired change of the estimates against its cup bias."""
    cols = [f"{w}{p}_pct" for w in WAYS for p in ("", "_low", "_high")]
    lines = [f"{rows['seed'].nunique()} campaigns, {len(rows)} runs (seeds {rows['seed'].min()}-{rows['seed'].max()}); "
             "mean relative bias (%) of the aerodynamic force read from the anemometer against the body's, "
             f"over the run / below {LOW_SPEED_MPS:g} m/s / above {HIGH_SPEED_MPS:g} m/s", ""]
    head = "| class | runs | " + " | ".join(f"{w} (all / low / high)" for w in WAYS) + " |"
    lines += [head, "|" + " --- |" * (2 + len(WAYS))]
    edges = np.quantile(rows["rms_yaw_deg"], [0.0, 0.25, 0.5, 0.75, 1.0])
    labels = [f"rms yaw {lo:.1f}-{hi:.1f} deg" for lo, hi in zip(edges[:-1], edges[1:])]
    rows = rows.assign(yaw_class=pd.cut(rows["rms_yaw_deg"], edges, labels=labels, include_lowest=True))
    for key in ("category", "yaw_class"):
        for name, g in rows.groupby(key, sort=True, observed=True):
            cells = [" / ".join(f"{g[f'{w}{p}_pct'].mean():+.2f}" for p in ("", "_low", "_high")) for w in WAYS]
            lines.append(f"| {name} | {len(g)} | " + " | ".join(cells) + " |")
    cells = [" / ".join(f"{rows[f'{w}{p}_pct'].mean():+.2f}" for p in ("", "_low", "_high")) for w in WAYS]
    lines.append(f"| all | {len(rows)} | " + " | ".join(cells) + " |")
    if records is not None:
        per = rows.groupby("seed")[cols].mean().reset_index()
        rec = records.merge(per, on="seed")
        lines += ["", f"{len(rec)} of these campaigns in the calibration records: correlation of the "
                  "campaign's mean over-speeding (cup_lag_corrected - air, %) with its z", "",
                  "| quantity | correlation | mean z, campaigns below / above the median bias |", "| --- | --- | --- |"]
        extra = rec["cup_lag_corrected_pct"] - rec["air_pct"]
        upper = extra > extra.median()
        for q in ("CD0", "KD", "F1_N_per_kph", "F2_N_per_kph2", "F50_N"):
            z = (rec[f"{q}_mean"] - rec[f"{q}_truth"]) / rec[f"{q}_sd"]
            lines.append(f"| {q} | {np.corrcoef(extra, z)[0, 1]:+.2f} | {z[~upper].mean():+.2f} / {z[upper].mean():+.2f} |")
    if probe is not None:
        first, second = (p.set_index("seed") for p in probe)
        per = rows.groupby("seed")["cup_lag_corrected_high_pct"].mean()
        common = per.index.intersection(first.index).intersection(second.index)
        lines += ["", f"{len(common)} campaigns of a withhold probe (the second arm without the anemometer's dynamics): "
                  "the paired change of the estimate (%) against the cup's bias above "
                  f"{HIGH_SPEED_MPS:g} m/s", "", "| quantity | mean paired change % | correlation with the bias |",
                  "| --- | --- | --- |"]
        for q in ("CD0", "KD", "F2_N_per_kph2", "F1_N_per_kph"):
            change = (second.loc[common, f"{q}_mean"] - first.loc[common, f"{q}_mean"]) / first.loc[common, f"{q}_truth"] * 100.0
            lines.append(f"| {q} | {change.mean():+.2f} | {np.corrcoef(per[common], change)[0, 1]:+.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs=2, metavar=("FIRST", "LAST"))
    ap.add_argument("--workers", type=int, default=2, help="Dask workers (0: in this process)")
    ap.add_argument("--out", type=Path, help="write the per-run rows here (CSV)")
    ap.add_argument("--from-records", type=Path, help="only summarise rows written before")
    ap.add_argument("--records", type=Path, help="a calibration run's records, to set the campaigns' z against the bias")
    ap.add_argument("--probe", type=Path, nargs=2, metavar=("FIRST", "SECOND"),
                    help="withhold_map_probe.py records of the default (FIRST) and of anemometer_dynamics withheld (SECOND)")
    a = ap.parse_args(argv)
    if a.from_records:
        rows = pd.read_csv(a.from_records)
    elif a.seeds:
        rows = simulate(range(a.seeds[0], a.seeds[1] + 1), a.workers)
        if a.out:
            rows.to_csv(a.out, index=False)
    else:
        ap.error("give --seeds or --from-records")
    records = pd.read_csv(a.records) if a.records else None
    probe = None
    if a.probe:
        arms = [pd.read_csv(p) for p in a.probe]
        probe = (arms[0][arms[0]["arm"] == "all"], arms[1][arms[1]["arm"] == "withheld"])
    print(summary(rows, records, probe))
    return 0


if __name__ == "__main__":
    sys.exit(main())
