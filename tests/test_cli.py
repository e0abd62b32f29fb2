"""The command line, end to end on small campaigns."""

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest

from bayes_roadload import config
from bayes_roadload.cli import EXIT_GATES_FAILED, EXIT_REFUSED, main
from bayes_roadload.data import load_campaign

SUMMARY_COLUMNS = ["parameter", "mean", "sd", "q2.5", "q50", "q97.5", "r_hat", "ess_bulk", "ess_tail"]


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "c14"
    assert main(["simulate", "--case", "14", "--pairs", "2", "--seed", "1", "--out", str(out)]) == 0
    return out


def test_simulate_writes_the_contract(campaign_dir):
    c = load_campaign(campaign_dir)
    assert c.run_ids == [1, 2, 3, 4] and c.directions() == {1: 1, 2: -1, 3: 1, 4: -1}
    truth = json.loads((campaign_dir / "truth.json").read_text())
    assert {"AD", "BD", "CD0", "KD"} <= set(truth) and truth["case"] == 14


def test_fit_lsq_writes_summary(campaign_dir, tmp_path, capsys):
    out = tmp_path / "fit"
    assert main(["fit", str(campaign_dir), "--method", "lsq", "--model", "three_term", "--out", str(out)]) == 0
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary.columns) == SUMMARY_COLUMNS
    assert {"AD", "BD", "CD0", "F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2"} <= set(summary["parameter"])
    cd0 = summary.set_index("parameter").loc["CD0"]
    # two pairs of case 14: CD0 within 5 % of the truth (pair spread ~0.8 %, pitch bias ~1 %)
    assert abs(cd0["mean"] - 0.4) < 0.02 and cd0["q2.5"] < cd0["mean"] < cd0["q97.5"]
    assert (out / "per_group.csv").exists() and json.loads((out / "fit.json").read_text())["method"] == "lsq"
    assert "CD0" in capsys.readouterr().out


def test_fit_refuses_bad_campaign_and_writes_nothing(tmp_path, capsys):
    bad = tmp_path / "bad"
    bad.mkdir()
    t = np.arange(20) * 0.25
    pd.DataFrame({"run": 1, "time_s": t, "speed_kph": 100.0 - t}).to_csv(bad / "runs.csv", index=False)
    (bad / "vehicle.toml").write_text("[vehicle]\nmass_kg = 1100.0\neffective_mass_kg = 1130.0\nfrontal_area_m2 = 1.85\n")
    out = tmp_path / "out"
    assert main(["fit", str(bad), "--method", "lsq", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "runs.csv" in err and "speed_kph" in err and "speed_mps" in err
    assert not out.exists()


def test_unknown_model_is_refused(campaign_dir, tmp_path, capsys):
    assert main(["fit", str(campaign_dir), "--model", "five_term", "--out", str(tmp_path / "o")]) == 2
    assert "five_term" in capsys.readouterr().err


def test_sensitivity_cases_models(tmp_path, capsys):
    csv = tmp_path / "sens.csv"
    assert main(["sensitivity", "--cross-wind", "0", "2", "--out", str(csv)]) == 0
    table = pd.read_csv(csv)
    assert set(table["parameter"]) == {"AD", "BD", "CD0", "KD"}
    assert main(["cases"]) == 0
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    assert "combined" in out and "three_term" in out and "four_term_driveline" in out


def test_demo_runs_and_prints_truth_beside_estimates(tmp_path, capsys):
    code = main(["demo", "--pairs", "1", "--warmup", "150", "--draws", "150", "--no-progress", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code in (0, 3)
    assert "truth" in out and "least squares" in out and "posterior" in out and "NUTS" in out
    assert (tmp_path / "campaign" / "runs.csv").exists()
    assert (tmp_path / "fit_lsq" / "summary.csv").exists()
    assert (tmp_path / "fit_nuts" / "posterior.nc").exists()


def test_fit_nuts_writes_outputs_and_flags_gates(campaign_dir, tmp_path, capsys):
    out = tmp_path / "nuts"
    code = main(["fit", str(campaign_dir), "--model", "three_term", "--warmup", "100", "--draws", "100",
                 "--no-progress", "--out", str(out)])
    printed = capsys.readouterr().out
    diag = json.loads((out / "diagnostics.json").read_text())
    assert code == (0 if diag["pass"] else 3)
    # a failed fit is announced before anything else is printed
    assert printed.startswith("!! NUTS FIT FAILED") == (not diag["pass"])
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary.columns) == SUMMARY_COLUMNS
    assert {"AD", "BD", "CD0", "F50_N"} <= set(summary["parameter"])
    assert (out / "posterior.nc").exists() and (out / "runs_summary.csv").exists()


def test_sampler_options_reach_the_sampler():
    from bayes_roadload.cli import _sampler, build_parser

    args = build_parser().parse_args(["fit", "campaign", "--out", "o", "--target-accept", "0.95", "--draws", "50",
                                      "--no-precondition"])
    s = _sampler(args)
    assert (s.target_accept, s.num_samples, s.precondition) == (0.95, 50, "none")
    assert _sampler(build_parser().parse_args(["fit", "campaign", "--out", "o"])).target_accept == \
        config.DEFAULT_SAMPLER.target_accept


@pytest.mark.slow
def test_fit_hierarchical_writes_tau_rows_and_run_rows(campaign_dir, tmp_path, capsys):
    """``--pooling hierarchical``: summary.csv gains tau_AD, tau_BD, tau_CD0 (positive, in the
    parameters' units), runs_summary.csv the run-level coefficients of every run.  Slow (a
    hierarchical NUTS fit, ~70 s); the same outputs of the same fit function are checked by
    tests/inference/test_hierarchical.py, and the option's plumbing by
    :func:`test_pooling_option_reaches_the_fit`."""
    out = tmp_path / "hier"
    code = main(["fit", str(campaign_dir), "--model", "three_term", "--pooling", "hierarchical", "--warmup", "150",
                 "--draws", "150", "--no-progress", "--out", str(out)])
    diag = json.loads((out / "diagnostics.json").read_text())
    assert code == (0 if diag["pass"] else 3)
    summary = pd.read_csv(out / "summary.csv").set_index("parameter")
    for k in ("AD", "BD", "CD0"):
        assert summary.loc[f"tau_{k}", "q2.5"] > 0
        assert summary.loc[f"tau_{k}", "mean"] < 0.5 * summary.loc[k, "mean"]
    runs = set(pd.read_csv(out / "runs_summary.csv")["parameter"])
    assert {f"{k}_run[{r}]" for k in ("AD", "BD", "CD0") for r in (1, 2, 3, 4)} <= runs


def test_pooling_option_reaches_the_fit(campaign_dir, tmp_path, monkeypatch):
    """``--pooling hierarchical`` (and the noise options) are handed to the NUTS fit; least
    squares refuses the option instead of ignoring it."""
    import bayes_roadload.inference.nuts as nuts

    seen = {}

    def fake_fit(campaign, spec, **kwargs):
        seen.update(kwargs)
        raise RuntimeError("stop here")

    monkeypatch.setattr(nuts, "fit_nuts", fake_fit)
    with pytest.raises(RuntimeError, match="stop here"):
        main(["fit", str(campaign_dir), "--model", "three_term", "--pooling", "hierarchical", "--noise", "white",
              "--no-progress", "--out", str(tmp_path / "h")])
    assert seen["pooling"] == "hierarchical" and seen["noise"] == "white"
    with pytest.raises(SystemExit, match="no hierarchical model"):
        main(["fit", str(campaign_dir), "--method", "lsq", "--pooling", "hierarchical", "--out", str(tmp_path / "l")])

def test_plan_from_a_fit_directory_writes_the_contract_files(tmp_path, capsys):
    """``plan FIT_DIR --target ... --confidence 0.95 --out DIR`` writes plan.csv with the contract
    columns (quantity, n_pairs, median_half_width, assurance), recommendation.csv,
    regulation.csv and the plot; a fit directory without fit.json is refused."""
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
    code = main(["plan", str(fit_dir), "--target", "CD0=1%", "--target", "F50_N=0.5%", "--confidence", "0.95",
                 "--pairs", "4", "--simulations", "2", "--out", str(out)])
    assert code == 0
    plan = pd.read_csv(out / "plan.csv")
    assert list(plan.columns[:4]) == ["quantity", "n_pairs", "median_half_width", "assurance"]
    assert set(plan["quantity"]) == {"CD0", "F50_N"} and set(plan["n_pairs"]) == {4}
    assert plan["assurance"].between(0, 1).all()
    assert (out / "plan.png").stat().st_size > 0
    assert {"quantity", "n_pairs", "reached"} <= set(pd.read_csv(out / "recommendation.csv").columns)
    reg = pd.read_csv(out / "regulation.csv")
    assert {"EEC", "GTR15"} <= set(reg["criterion"])
    printed = capsys.readouterr().out
    assert "pairs needed" in printed and "Regulation precision" in printed


def test_import_vbox_and_fit_an_interval_campaign(tmp_path, capsys):
    """import-vbox on synthetic VBOX exports (high and low window, one run the operator turned
    Off), then fit: the Off run and its partner are rejected and reported."""
    from bayes_roadload.data import IntervalCampaign, Vehicle
    from bayes_roadload.data.vbox import write_vbox_csv

    rng = np.random.default_rng(4)
    me, f0, c = 1530.0, 100.0, 0.4
    k = np.sqrt(f0 * c)

    def window(gates_kph, runs, off=()):
        g = np.asarray(gates_kph) / 3.6
        rows = [{"run": r + 1, "window": "w", "direction": 1 - 2 * (r % 2), "valid": 0 if r + 1 in off else 1,
                 "speed_start_mps": g[j], "speed_end_mps": g[j + 1],
                 "interval_s": me / k * (np.arctan(c * g[j] / k) - np.arctan(c * g[j + 1] / k)) + rng.normal(0, 0.05)}
                for r in range(runs) for j in range(len(g) - 1)]
        return IntervalCampaign(pd.DataFrame(rows), Vehicle(1500.0, me, 2.2))

    high = write_vbox_csv(window((95, 90, 85, 80, 75, 70), 6, off=(3,)), tmp_path / "high.csv")
    low = write_vbox_csv(window((50, 45, 40, 35), 6), tmp_path / "low.csv")
    (tmp_path / "vehicle.toml").write_text("[vehicle]\nmass_kg = 1500.0\neffective_mass_kg = 1530.0\n"
                                           "frontal_area_m2 = 2.2\n")
    out = tmp_path / "camp"
    assert main(["import-vbox", str(high), str(low), "--out", str(out)]) == EXIT_REFUSED   # no vehicle
    assert main(["import-vbox", str(high), str(low), "--vehicle", str(tmp_path / "vehicle.toml"),
                 "--out", str(out)]) == 0
    assert len(load_campaign(out).run_ids) == 12 and (out / "import_report.json").exists()
    code = main(["fit", str(out), "--out", str(tmp_path / "fit"), "--warmup", "200", "--draws", "300",
                 "--no-progress"])
    text = capsys.readouterr().out
    assert code in (0, EXIT_GATES_FAILED)
    assert "rejected run high-3: operator: Run-Use Off" in text and "rejected run high-4: partner of high-3" in text
    summary = pd.read_csv(tmp_path / "fit" / "summary.csv").set_index("parameter")
    # F0 = M g AD = 100 N and F2 = c / 3.6^2 within 4 posterior sd
    assert abs(summary.loc["F0_N", "mean"] - f0) < 4 * summary.loc["F0_N", "sd"]
    assert abs(summary.loc["F2_N_per_kph2", "mean"] - c / 3.6**2) < 4 * summary.loc["F2_N_per_kph2", "sd"]
    assert len(pd.read_csv(tmp_path / "fit" / "runs_summary.csv")) == 10


def test_simulate_and_fit_a_distance_time_campaign_at_two_masses(tmp_path, capsys):
    """simulate --masses --markers writes distances.csv (one pair at 1100 kg, one at 1400 kg,
    timed past 5 markers 300 m apart); fit takes the kind: one joint NUTS fit of both masses
    (few draws: the gates may fail, the estimates must still hold the truth)."""
    assert main(["simulate", "--case", "2", "--masses", "-5", "--out", str(tmp_path / "bad")]) == EXIT_REFUSED
    assert "physical range" in capsys.readouterr().err and not (tmp_path / "bad").exists()
    camp = tmp_path / "dt"
    assert main(["simulate", "--case", "1", "--pairs", "2", "--seed", "2", "--masses", "1100", "1400",
                 "--markers", "100:300:1300", "--timing-sd", "0.01", "--out", str(camp)]) == 0
    assert "timed past 5 markers (100-1300 m, timing sd 0.01 s)" in capsys.readouterr().out
    c = load_campaign(camp)
    assert c.kind == "distances" and c.masses_kg() == {1: 1100.0, 2: 1100.0, 3: 1400.0, 4: 1400.0}
    assert main(["fit", str(camp), "--method", "lsq", "--out", str(tmp_path / "no")]) == EXIT_REFUSED
    assert "--method nuts only" in capsys.readouterr().err and not (tmp_path / "no").exists()
    assert main(["fit", str(camp), "--validity", "report", "--out", str(tmp_path / "no")]) == EXIT_REFUSED
    assert "--validity" in capsys.readouterr().err and not (tmp_path / "no").exists()
    out = tmp_path / "fit"
    code = main(["fit", str(camp), "--model", "three_term", "--out", str(out), "--warmup", "150", "--draws", "150",
                 "--target-accept", "0.9", "--no-progress"])
    text = capsys.readouterr().out
    assert code in (0, EXIT_GATES_FAILED) and "4 runs at 1100, 1400 kg, 20 marker passings" in text
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary.columns) == SUMMARY_COLUMNS
    s = summary.set_index("parameter")
    truth = json.loads((camp / "truth.json").read_text())
    # case 1's 1 m/s head and cross wind is not in the still-air model: a small bias against
    # the posterior sd (AD 19 %, CD0 12 % with 4 runs past 5 markers, measured); within 3 sd
    for name in ("AD", "CD0"):
        assert abs(s.loc[name, "mean"] - truth[name]) < 3 * s.loc[name, "sd"], name
    runs = pd.read_csv(out / "runs_summary.csv")
    assert runs["mass_kg"].tolist() == [1100.0, 1100.0, 1400.0, 1400.0]
    assert runs["v0_mps_mean"].between(25.0, 31.3).all() and runs["v0_mps_sd"].lt(0.2).all()
    diag = json.loads((out / "diagnostics.json").read_text())
    assert diag["kind"] == "distances" and diag["runs_fitted"] == 4
