"""ArviZ data, summary.csv, diagnostics.json and the derived road load."""

import json

import arviz as az
import numpy as np
import pandas as pd
import pytest

from bayes_roadload import config
from bayes_roadload.inference.results import (
    SUMMARY_COLUMNS,
    posterior_predictive,
    to_inference_data,
    trace_report,
    truth_derived,
)
from bayes_roadload.output import write_fit_dir


@pytest.fixture(scope="module")
def outputs(pooled_fit, tmp_path_factory):
    out = tmp_path_factory.mktemp("nuts")
    report = trace_report(pooled_fit)
    write_fit_dir(report, out)
    return out, report.summary, report.diagnostics


def test_files_and_columns(outputs):
    out, summary, diag = outputs
    csv = pd.read_csv(out / "summary.csv")
    assert tuple(csv.columns) == SUMMARY_COLUMNS
    rows = set(csv["parameter"])
    assert {"AD", "BD", "CD0", "KD", "F50_N", "F50_tyre_N", "F50_aero_N", "F50_driveline_N",
            "F50_undriven_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2", "q_mps_per_sqrt_s"} <= rows
    d = json.loads((out / "diagnostics.json").read_text())
    for k in ("divergences", "max_r_hat", "min_ess_bulk", "mean_tree_depth", "bfmi", "pass", "gates"):
        assert k in d
    runs = pd.read_csv(out / "runs_summary.csv")
    assert "v0_mps[1]" in set(runs["parameter"]) and "sigma_mps[4]" in set(runs["parameter"])


def test_posterior_nc_groups_and_run_coordinates(outputs):
    out, _, _ = outputs
    idata = az.from_netcdf(str(out / "posterior.nc"))
    for g in ("posterior", "posterior_predictive", "log_likelihood", "observed_data", "constant_data", "sample_stats"):
        assert hasattr(idata, g), g
    assert list(idata.posterior["v0_mps"].dims) == ["chain", "draw", "run"]
    assert list(idata.log_likelihood["speed_mps"].dims) == ["chain", "draw", "run"]
    assert list(idata.posterior.coords["run"].values) == ["1", "2", "3", "4"]
    # the per-run log-likelihood supports model comparison
    assert np.isfinite(float(az.loo(idata).elpd_loo))


def test_derived_road_load_is_consistent(pooled_fit):
    idata = to_inference_data(pooled_fit, predictive=False)
    post = idata.posterior
    parts = sum(post[f"F50_{p}_N"] for p in ("tyre", "aero", "driveline", "undriven"))
    np.testing.assert_allclose(post["F50_N"], parts, rtol=1e-12)
    truth = truth_derived(pooled_fit.problem, pooled_fit.truth)
    f50 = post["F50_N"].values.ravel()
    # the total road load is far better determined than its parts; the truth is within 4 sd
    assert abs(f50.mean() - truth["F50_N"]) < 4 * f50.std()
    assert f50.std() / f50.mean() < 0.01


def test_posterior_predictive_covers_the_observed_speeds(pooled_fit):
    """About 95 % of the measured speeds lie inside the 95 % predictive band (not per-run
    independent, hence the wide acceptance 0.85-0.995)."""
    pred = posterior_predictive(pooled_fit, n_draws=100)
    pp = pred["speed_mps"]
    # stored in float32: what the traces lose to it is below the likelihood's noise floor
    assert pp.dtype == pred["speed_integrated_mps"].dtype == np.float32
    assert np.nanmax(np.abs(pp)) * np.finfo(np.float32).eps < config.SPEED_NOISE_FLOOR_MPS / 100
    flat = pp.reshape((-1,) + pp.shape[2:])
    lo, hi = np.nanpercentile(flat, [2.5, 97.5], axis=0)
    obs = np.asarray(pooled_fit.problem.batch.speed_mps)
    mask = np.asarray(pooled_fit.problem.batch.mask)
    inside = ((obs >= lo) & (obs <= hi))[mask].mean()
    assert 0.85 < inside < 0.995, inside
