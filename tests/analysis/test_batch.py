"""Tests of the batch door for many fits (:mod:`bayes_roadload.analysis.batch`).

One real NUTS fit (1 pair, 100 + 100 draws: about 30 s, mostly compilation) through the door in
this process; the 2-worker Dask ``LocalCluster`` (x64 and core sharing in the workers) is in the
slow set, since tests/analysis/test_fleet.py runs fits on such a cluster in the default suite;
everything else uses jobs that fail at once or synthetic records.
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pandas as pd
import pytest

from bayes_roadload import config
from bayes_roadload.analysis.batch import (FitJob, SimulatedCampaign, _interval_fields, batch_client, batch_map,
                                           coverage_summary, run_batch, run_fit_job, worker_environment)

from ..conftest import clean_case

TINY_SAMPLER = config.SamplerConfig(num_warmup=100, num_samples=100, num_chains=2, seed=5)


def _broken_campaign():
    raise RuntimeError("no such campaign")


class MapOnly:
    """The smallest executor: ``map`` is the builtin, and the calls are counted."""

    def __init__(self):
        self.calls = 0

    def map(self, fn, iterable):
        self.calls += 1
        return map(fn, iterable)


def _good_job():
    return FitJob("good", SimulatedCampaign(clean_case(), pairs=1, seed=3, driveline=True), model="three_term",
                  noise="white", sampler=TINY_SAMPLER, tags={"arm": "a"})


class RaisingJob:
    """A job whose ``run()`` raises (a job type that breaks the no-raise rule)."""

    name = "raising"

    def run(self):
        raise ZeroDivisionError("bad job")


def _worker_facts(_):
    import os

    import jax
    import jax.numpy as jnp

    return {"pid": os.getpid(), "dtype": jnp.zeros(1).dtype.name, "devices": jax.local_device_count()}


@pytest.fixture(scope="module")
def client():
    with batch_client(workers=2) as c:
        yield c


@pytest.fixture(scope="module")
def batch():
    seen = []
    jobs = [_good_job(), FitJob("broken", _broken_campaign, model="three_term", sampler=TINY_SAMPLER), RaisingJob()]
    return run_batch(jobs, on_record=seen.append), seen


@pytest.mark.slow  # a cluster of its own; the fleet tests run fits on a 2-worker cluster by default
def test_cluster_workers(client):
    info = client.scheduler_info()["workers"]
    assert len(info) == 2 and all(w["nthreads"] == 1 for w in info.values())
    facts = batch_map(_worker_facts, range(4), client, progress=False)
    # every worker computes in 64-bit and has its share of the cores as XLA host devices
    share = int(worker_environment(2)["XLA_FLAGS"].split("device_count=")[1].split()[0])
    assert all(f["dtype"] == "float64" and f["devices"] == share for f in facts)
    assert all(f["pid"] != __import__("os").getpid() for f in facts)


def test_order_kept_and_every_record_seen(batch):
    df, seen = batch
    assert list(df["name"]) == ["good", "broken", "raising"]
    assert sorted(r["name"] for r in seen) == ["broken", "good", "raising"]


def test_raising_job_is_recorded(batch):
    df, _ = batch
    raising = df.iloc[2]
    assert raising["error"] == "ZeroDivisionError: bad job"
    assert "bad job" in raising["traceback"]


def test_executor_map_is_used():
    executor = MapOnly()
    jobs = [FitJob(f"broken{i}", _broken_campaign) for i in range(3)]
    df = run_batch(jobs, executor=executor)
    assert executor.calls == 1 and list(df["name"]) == ["broken0", "broken1", "broken2"]
    with pytest.raises(TypeError):
        run_batch(jobs, executor, executor=executor)


def test_batch_map_errors_in_process(capsys):
    assert batch_map(abs, [-1, 2], progress=False) == [1, 2]
    with pytest.raises(TypeError):
        batch_map(abs, ["x"], progress=False)
    out = batch_map(abs, [-3, "x", 4], on_error=lambda item, exc, tb: type(exc).__name__)
    assert out == [3, "TypeError", 4]
    # not a terminal: one line per item with the count and the time left
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 3 and lines[1].startswith("batch 2/3 #1: failed") and "left]" in lines[2]


def test_record_keys_and_values(batch):
    df, _ = batch
    good = df.iloc[0]
    assert good["error"] is None or (isinstance(good["error"], float) and math.isnan(good["error"]))
    assert good["arm"] == "a" and good["noise"] == "white" and good["seed"] == 3 and good["n_runs"] == 2
    assert good["parameters"] == "AD,BD,CD0"
    for q in ("AD", "BD", "CD0", "F50_N"):
        ends = [good[f"{q}_{k}"] for k in ("q2.5", "q5", "q25", "q50", "q75", "q95", "q97.5")]
        assert np.all(np.diff(ends) >= 0), q
        assert good[f"{q}_sd"] > 0 and math.isfinite(good[f"{q}_truth"])
        assert good[f"{q}_in95"] == (good[f"{q}_q2.5"] <= good[f"{q}_truth"] <= good[f"{q}_q97.5"])
        # the budget's columns (analysis.budget.budget_record): the interval's sd is the posterior's
        # and the sources' added in quadrature, to the Monte Carlo error of 200 draws (an sd's
        # relative SE ~ 1 / sqrt(2 n) = 5 %; 5 SE allowed)
        typeb = [good[c] for c in df.columns if c.startswith(f"{q}_sd_typeb_") and math.isfinite(good[c])]
        assert good[f"{q}_sd_data"] > 0 and typeb and min(typeb) >= 0, q
        assert good[f"{q}_sd"] == pytest.approx(math.sqrt(good[f"{q}_sd_data"] ** 2 + sum(v**2 for v in typeb)),
                                                rel=5 / math.sqrt(2 * 200)), q
    assert 0 < good["time_compile_s"] < good["time_total_s"]
    # the draws are not in the record, only scalars
    assert all(np.ndim(v) == 0 for v in good.to_dict().values())
    for key in ("gate_pass", "gates_failed", "divergences", "max_r_hat", "min_ess_bulk", "time_map_s",
                "time_warmup_s", "time_sampling_s", "time_fit_s", "time_total_s", "time_compile_s", "rss_mb", "memory_maps",
                "jax_caches_cleared", "sigma_mps_mean", "target_accept_sampled"):
        assert key in df.columns, key
    # the job asked for 0.8; two runs are sampled at the small-campaign acceptance
    assert good["target_accept"] == TINY_SAMPLER.target_accept
    assert good["target_accept_sampled"] == TINY_SAMPLER.small_campaign_target_accept
    # the 1-pair posterior is tight: the truth is well inside +-10 sd of the mean (a loose check
    # that the record is about this fit, not a statistical test)
    assert abs(good["CD0_mean"] - good["CD0_truth"]) < 10 * good["CD0_sd"]
    # SBC ranks are out of every post-warm-up draw; mean |yaw| is the logged channel's
    assert good["rank_draws"] == TINY_SAMPLER.num_chains * TINY_SAMPLER.num_samples
    assert 0 <= good["CD0_rank"] <= good["rank_draws"]
    assert 0.0 < good["mean_abs_yaw_rad"] < 0.5


def test_error_is_captured(batch):
    df, _ = batch
    broken = df.iloc[1]
    assert broken["error"] == "RuntimeError: no such campaign"
    assert "no such campaign" in broken["traceback"]
    assert math.isnan(broken["CD0_mean"])


def test_sequential_default_and_pickling():
    jobs = [FitJob(f"broken{i}", _broken_campaign) for i in range(2)]
    df = run_batch(jobs)
    assert list(df["name"]) == ["broken0", "broken1"] and df["error"].notna().all()
    job = _good_job()
    assert pickle.loads(pickle.dumps(job)) == job
    rec = run_fit_job(jobs[0])
    assert pickle.loads(pickle.dumps(rec)) == rec


def test_interval_fields_normal_draws():
    # 200 000 N(0, 1) draws: the sample 2.5 % quantile has a standard error of
    # sqrt(0.025 * 0.975 / n) / phi(1.96) = 0.006, so 0.03 is a 5-sigma tolerance.
    x = np.random.default_rng(0).standard_normal(200_000)
    out = _interval_fields("X", x, 1.8, (0.5, 0.9, 0.95))
    assert out["X_q2.5"] == pytest.approx(-1.96, abs=0.03)
    assert out["X_q75"] == pytest.approx(0.674, abs=0.03)
    assert (out["X_in50"], out["X_in90"], out["X_in95"]) == (False, False, True)
    assert _interval_fields("X", x, None, (0.95,))["X_in95"] is None
    # the SBC rank: draws below the truth (Phi(1.8) = 0.964 of them, binomial sd 0.0004 n)
    assert out["X_rank"] == pytest.approx(0.9641 * x.size, abs=0.002 * x.size)
    assert _interval_fields("X", x, None, (0.95,))["X_rank"] is None


def test_coverage_summary_counts():
    flags = [True] * 18 + [False] * 2
    df = pd.DataFrame({"noise": ["white"] * 20, "error": [None] * 20, "X_truth": 0.0,
                       "X_mean": np.linspace(-1, 1, 20), "X_sd": 1.0, "X_in95": flags})
    out = coverage_summary(df, by=("noise",), levels=(0.95,))
    row = out.iloc[0]
    assert (row["n"], row["covered"], row["coverage"]) == (20, 18, 0.9)
    assert row["se_nominal"] == pytest.approx(math.sqrt(0.95 * 0.05 / 20))
    assert row["wilson_low"] < 0.9 < row["wilson_high"]
    assert row["z_sd"] == pytest.approx(np.std(np.linspace(-1, 1, 20), ddof=1))


def test_one_worker_runs_in_process():
    with batch_client(workers=1) as c:
        assert c is None  # run_batch then runs the jobs in this process


def test_worker_environment_shares_cores(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "--xla_dump_to=/tmp/x --xla_force_host_platform_device_count=8")
    env = worker_environment(3, cores=8)
    flags = env["XLA_FLAGS"].split()
    assert "--xla_dump_to=/tmp/x" in flags  # other flags kept
    assert [f for f in flags if "device_count" in f] == ["--xla_force_host_platform_device_count=2"]
    assert "intra_op_parallelism_threads=1" in flags and env["OMP_NUM_THREADS"] == "1"
    assert "device_count=1" in worker_environment(4, cores=2)["XLA_FLAGS"]


def test_the_time_left_weighs_each_item_by_its_work(monkeypatch):
    """Items of weights 1 and 9: after the first, done in 10 s, the other is expected to take
    9 x 10 s (equal weights would say 10 s)."""
    import io

    from bayes_roadload.analysis import batch

    clock = iter([100.0, 110.0, 200.0])
    monkeypatch.setattr(batch.time, "perf_counter", lambda: next(clock))
    out = io.StringIO()
    bar = batch._Progress(2, True, "fits", stream=out, weights=[1.0, 9.0])
    bar.update("small", index=0)
    assert "about " + batch._format_seconds(90.0) + " left" in out.getvalue()
    bar.update("large", index=1)
    assert out.getvalue().splitlines()[-1].endswith("about " + batch._format_seconds(0.0) + " left]")


@pytest.mark.parametrize("maps, cleared", [((1000, 65530), False), ((40000, 65530), True)])
def test_caches_are_cleared_when_the_process_nears_its_mapping_limit(monkeypatch, maps, cleared):
    """JAX's caches are cleared after a job once the process holds more memory mappings than
    the share of the kernel's limit (compiled code lives in mappings of its own)."""
    import jax

    from bayes_roadload.analysis import batch

    calls = []
    monkeypatch.setattr(batch, "_map_count", lambda: maps)
    monkeypatch.setattr(batch, "_rss_mb", lambda: 100.0)  # memory far below its own threshold
    monkeypatch.setattr(jax, "clear_caches", lambda: calls.append(1))
    rec = run_fit_job(FitJob("broken", _broken_campaign, model="three_term", sampler=TINY_SAMPLER))
    assert rec["memory_maps"] == maps[0]
    assert rec["jax_caches_cleared"] is cleared and len(calls) == int(cleared)
    assert (maps[0] > batch.CLEAR_JAX_CACHES_ABOVE_MAP_SHARE * maps[1]) is cleared


@pytest.mark.slow  # a cross-check kept out of the default run's 10 minutes
def test_a_laplace_record_carries_the_model_constants_type_b(tmp_path):
    """A MAP + Laplace job's intervals carry the Type B uncertainty of the model's constants, as
    the NUTS record and ``fit`` do: the pitch default's K_alpha (0.9 rad^-1) with a standard
    uncertainty of 5 against 0, the same campaign and seed otherwise.  On the thesis car a unit
    of K_alpha moves F50_N by ~3 N against a posterior sd of ~4 N, so u = 5 must widen F50_N's
    interval several-fold; the Type B draws' Monte Carlo error on an sd is ~2 %, so a ratio above
    1.2 is the source, and a record that leaves the constant out (ratio 1) fails."""
    from pathlib import Path

    from bayes_roadload.inference.spec import MODELS_DIR

    text = Path(MODELS_DIR, "four_term_tyre_lag_admittance_pitch.toml").read_text()
    stated = "[parameters.Kalpha]\nfixed = 0.9\nuncertainty = 0.5\n"
    assert stated in text
    models = []
    for u in (5.0, 0.0):
        path = tmp_path / f"pitch_kalpha_u{u:g}.toml"
        path.write_text(text.replace(stated, f"[parameters.Kalpha]\nfixed = 0.9\nuncertainty = {u}\n"))
        models.append(str(path))
    on_rec, off_rec = (run_fit_job(FitJob(f"laplace-{i}", SimulatedCampaign(3, 1, 0), model=m, method="laplace",
                                          pooling="pooled")) for i, m in enumerate(models))
    assert on_rec["error"] is None and off_rec["error"] is None, (on_rec.get("traceback"), off_rec.get("traceback"))
    assert on_rec["F50_N_sd"] > 1.2 * off_rec["F50_N_sd"]
    # the budget's columns name the constant's share: present where it is a source, absent where switched off
    assert on_rec["F50_N_sd_typeb_Kalpha"] > 0 and "F50_N_sd_typeb_Kalpha" not in off_rec
