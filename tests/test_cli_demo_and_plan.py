"""The command line end to end: the demo (README's first command) and planning from a fit
directory.  A module of their own beside ``test_cli.py``: the two are the longest command-line
tests, and the test runs distribute whole modules over their worker processes."""

import dataclasses
import json

import pandas as pd

from bayes_roadload.analysis.planning import half_widths
from bayes_roadload.cli import EXIT_REFUSED, main


def test_demo_runs_and_prints_truth_beside_estimates(tmp_path, capsys):
    code = main(["demo", "--pairs", "1", "--warmup", "150", "--draws", "150", "--no-progress", "--pooling", "pooled",
                 "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code in (0, 3)
    assert "truth" in out and "least squares" in out and "posterior" in out and "NUTS" in out
    assert (tmp_path / "campaign" / "runs.csv").exists()
    assert (tmp_path / "fit_lsq" / "summary.csv").exists()
    assert (tmp_path / "fit_nuts" / "posterior.nc").exists()
    # without --model each fit takes fit's default model for its method
    from bayes_roadload.inference.kinds import KINDS, FitOptions

    for fit_dir, method in (("fit_lsq", "lsq"), ("fit_nuts", "nuts")):
        expected = KINDS["traces"].default_model(None, FitOptions(method=method))
        assert json.loads((tmp_path / fit_dir / "fit.json").read_text())["model"] == expected
    # the statement on the intervals counts what summary.csv and the truth say
    summary = pd.read_csv(tmp_path / "fit_nuts" / "summary.csv").set_index("parameter")
    truth = json.loads((tmp_path / "campaign" / "truth.json").read_text())
    names = ["AD", "BD", "CD0", "KD"]
    ok = sum(summary.loc[k, "q2.5"] <= truth[k] <= summary.loc[k, "q97.5"] for k in names)
    line = next(x for x in out.splitlines() if x.startswith("The posterior 95 % intervals contain"))
    n = int(line.split(" of ")[1].split()[0])
    k = int(line.split("truth for ")[1].split()[0])
    assert n >= len(names) and k <= n and (n - k) >= (len(names) - ok)


def test_plan_from_a_fit_directory_writes_the_contract_files(tmp_path, capsys, monkeypatch):
    """``plan FIT_DIR --target ... --confidence 0.95 --out DIR`` writes plan.csv with the contract
    columns (quantity, n_pairs, median_half_width, assurance), recommendation.csv,
    regulation.csv, type_b_floors.csv and the plot; a fit directory without fit.json is refused.
    A target below its Type B floor (CD0 to 1 % with the default anemometer uncertainty) is
    reported not reachable, and the refits' intervals are at least that floor; with
    ``--no-type-b`` they are narrower and no floor applies."""
    import warnings

    import arviz as az
    import numpy as np

    from bayes_roadload.data import save_campaign
    from bayes_roadload.simulate import simulate_campaign

    from .conftest import clean_case

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        campaign = simulate_campaign(dataclasses.replace(clean_case(), measurement_noise=False), pairs=2, seed=5)
    save_campaign(campaign, tmp_path / "campaign")
    fit_dir = tmp_path / "fit"
    fit_dir.mkdir()
    rng = np.random.default_rng(0)
    posterior = {k: campaign.truth[k] * (1 + 0.01 * rng.standard_normal((2, 50))) for k in ("AD", "BD", "CD0")}
    posterior["sigma_mps"] = np.full((2, 50, 4), 0.05)
    posterior["q_mps_per_sqrt_s"] = np.full((2, 50), 0.002)
    az.from_dict(posterior=posterior).to_netcdf(str(fit_dir / "posterior.nc"))
    code = main(["plan", str(fit_dir), "--out", str(tmp_path / "refused")])
    assert code == EXIT_REFUSED and "fit.json" in capsys.readouterr().err
    (fit_dir / "fit.json").write_text(json.dumps({"model": "three_term", "model_file": None,
                                                  "free": ["AD", "BD", "CD0"], "pooling": "pooled",
                                                  "campaign": str(tmp_path / "campaign")}))
    out = tmp_path / "plan"
    args = ["plan", str(fit_dir), "--target", "CD0=1%", "--target", "F50_N=3%", "--confidence", "0.95",
            "--pairs", "2", "--simulations", "2", "--workers", "1"]
    code = main(args + ["--out", str(out)])
    assert code == 0
    plan = pd.read_csv(out / "plan.csv")
    assert list(plan.columns[:4]) == ["quantity", "n_pairs", "median_half_width", "assurance"]
    assert set(plan["quantity"]) == {"CD0", "F50_N"} and set(plan["n_pairs"]) == {2}
    assert plan["assurance"].between(0, 1).all()
    assert (out / "plan.png").stat().st_size > 0
    rec = pd.read_csv(out / "recommendation.csv").set_index("quantity")
    assert {"n_pairs", "reached", "type_b_half_width", "reachable"} <= set(rec.columns)
    floors = pd.read_csv(out / "type_b_floors.csv").set_index("quantity")
    assert not floors.loc["CD0", "reachable"] and floors.loc["CD0", "main_source"] == "airspeed_factor_rel"
    assert not rec.loc["CD0", "reached"] and pd.isna(rec.loc["CD0", "n_pairs"])
    # every refit's interval carries the floor: 0.9 allows the Monte Carlo error of a 95 %
    # half-width read from 2000 draws (~3 %) three times over
    records = pd.read_csv(out / "plan_records.csv")
    assert records["type_b"].all()
    cd0 = plan.set_index("quantity").loc["CD0"]
    assert cd0["q10_half_width"] >= 0.9 * floors.loc["CD0", "type_b_half_width"]
    reg = pd.read_csv(out / "regulation.csv")
    assert {"EEC", "GTR15"} <= set(reg["criterion"])
    printed = capsys.readouterr().out
    assert "pairs needed" in printed and "Regulation precision" in printed
    assert "NOT REACHABLE" in printed and "none (Type B floor)" in printed
    assert "vehicle.toml [uncertainty] for airspeed_factor_rel" in printed   # a campaign's source, not a model's
    # the simulations come in steps (config.PLAN_STEPS: here 1 of the 2), the second only where
    # a target's assurance is still undecided after the first (its Wilson interval holds 0.8)
    # (one refit meeting the target: Wilson interval 0.21-1; one missing it: 0-0.79, decided)
    f50 = plan.set_index("quantity").loc["F50_N"]
    first_met = bool(half_widths(records[records["simulation"] == 0], "F50_N", 0.95).iloc[0] <= 3.0)
    assert int(f50["n_sims"]) == len(records) == (2 if first_met else 1)
    assert ("undecided after 1 simulations at [2] pairs" in printed) == first_met

    # every target below its floor: answered from the floors alone, nothing refitted; a source
    # fit that failed its gates is named first, with the gates it failed
    (fit_dir / "diagnostics.json").write_text(json.dumps({"pass": False, "failed": ["rhat"]}))
    code = main(["plan", str(fit_dir), "--target", "CD0=1%", "--pairs", "2", "--simulations", "2", "--workers", "1",
                 "--out", str(tmp_path / "floor_only")])
    (fit_dir / "diagnostics.json").unlink()
    printed = capsys.readouterr().out
    assert printed.startswith(f"!! the source fit {fit_dir} FAILED its diagnostic gates (rhat): the plan below draws "
                              "from a posterior that is not trustworthy")
    assert code == 0 and "nothing simulated" in printed and "refitting" not in printed
    only = pd.read_csv(tmp_path / "floor_only" / "recommendation.csv").set_index("quantity")
    assert not only.loc["CD0", "reached"] and not only.loc["CD0", "reachable"]
    assert pd.read_csv(tmp_path / "floor_only" / "plan.csv").empty

    # --confirm: the recommended size refitted by NUTS (one campaign, short chains), beside its
    # Laplace refit of the same campaign, on the plan's own batch client (one cluster started)
    from bayes_roadload.analysis import batch

    opened = []
    real_client = batch.batch_client
    monkeypatch.setattr(batch, "batch_client", lambda *a, **k: opened.append(a) or real_client(*a, **k))
    code = main(args + ["--no-type-b", "--confirm", "1", "--warmup", "100", "--draws", "100",
                        "--out", str(tmp_path / "data_only")])
    assert code == 0 and not (tmp_path / "data_only" / "type_b_floors.csv").exists()
    assert len(opened) == 1
    confirm = pd.read_csv(tmp_path / "data_only" / "confirm.csv")
    reached = pd.read_csv(tmp_path / "data_only" / "recommendation.csv").query("reached")
    assert len(reached) and set(confirm["n_pairs"]) == set(reached["n_pairs"].astype(int))
    assert (confirm["campaigns"] == 1).all() and (confirm["median_ratio"] > 0).all()
    assert confirm["nuts_assurance"].isin([0.0, 1.0]).all()
    assert "Confirming with NUTS" in capsys.readouterr().out
    # more NUTS refits than campaigns simulated at every size (the first step of --simulations 2): refused
    code = main(args + ["--confirm", "2", "--out", str(tmp_path / "too_many")])
    assert code == EXIT_REFUSED and "--confirm" in capsys.readouterr().err
    data_only = pd.read_csv(tmp_path / "data_only" / "plan.csv").set_index("quantity")
    assert data_only.loc["CD0", "median_half_width"] < cd0["median_half_width"]
    assert "reachable" not in pd.read_csv(tmp_path / "data_only" / "recommendation.csv").columns
