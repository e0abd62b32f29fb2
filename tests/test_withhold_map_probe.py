"""benchmarks/withhold_map_probe.py: the paired table of a probe's records (one per second arm)."""

import re

import pandas as pd
import pytest

from .conftest import benchmark_script


@pytest.fixture(scope="module")
def probe():
    with benchmark_script("withhold_map_probe") as module:
        yield module


def _records(arm, errors_pct, withheld="", arm_model="default", names=("ind-1", "ind-2")):
    truth = [{"ind-1": 0.4, "ind-2": 0.5, "ind-3": 0.6}[n] for n in names]
    return pd.DataFrame({"name": list(names), "arm": arm, "withheld": withheld, "arm_model": arm_model,
                         "CD0_truth": truth, "CD0_mean": [t * (1 + e / 100) for t, e in zip(truth, errors_pct)]})


def _row(table, quantity):
    line = next(x for x in table.splitlines() if x.startswith(f"| {quantity} |"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_each_second_arm_is_paired_with_the_first_seed_by_seed(probe):
    """Errors -4 and -2 % with every effect; -1 and -2 % with pitch withheld (changes +3, 0:
    mean +1.5, SE sd / sqrt 2 = 1.5); -3 and +1 % with a variant (changes +1, +3: +2.0, SE 1.0)."""
    records = pd.concat([_records("all", [-4.0, -2.0]), _records("withheld", [-1.0, -2.0], withheld="pitch"),
                         _records("withheld", [-3.0, 1.0], arm_model="variant")], ignore_index=True)
    tables = re.split(r"\n\n(?=\d+ campaigns)", probe.summary(records))
    assert len(tables) == 2
    withheld = next(t for t in tables if "withheld pitch, model default" in t)
    variant = next(t for t in tables if "withheld none, model variant" in t)
    assert _row(withheld, "CD0") == ["CD0", "-3.00", "-1.50", "+1.50 (1.50)"]
    assert _row(variant, "CD0") == ["CD0", "-3.00", "-1.00", "+2.00 (1.00)"]
    assert "2 campaigns (ind-1, ind-2)" in withheld


def test_a_seed_missing_from_one_arm_is_left_out_of_the_pairs(probe):
    records = pd.concat([_records("all", [-4.0, -2.0]),
                         _records("withheld", [0.0], withheld="pitch", names=("ind-2",))], ignore_index=True)
    table = probe.summary(records)
    assert "1 campaigns (ind-2)" in table
    assert _row(table, "CD0")[1:3] == ["-2.00", "+0.00"]


def test_the_held_intervals_and_the_sd_ratio_are_counted_per_arm_on_the_paired_seeds(probe):
    """Both arms' intervals over the seeds they share: the first holds the truth on ind-1 only, the
    second on both; the second's sd is 1.5x and 2.5x the first's (median 2.0); ind-3, fitted in
    the second arm alone, is left out."""
    first = _records("all", [-4.0, -2.0]).assign(CD0_in95=[True, False], CD0_sd=[0.01, 0.02])
    second = _records("withheld", [-4.0, -2.0, 0.0], arm_model="variant", names=("ind-1", "ind-2", "ind-3")
                      ).assign(CD0_in95=[True, True, False], CD0_sd=[0.015, 0.05, 1.0])
    table = probe.summary(pd.concat([first, second], ignore_index=True))
    rows = [line for line in table.splitlines() if line.startswith("| CD0 |")]
    assert [c.strip() for c in rows[1].strip("|").split("|")] == ["CD0", "1 of 2", "2 of 2", "2.000"]
    assert "| all | 1 of 2 | 2 of 2 | |" in table


def test_each_arm_is_fitted_with_its_own_models(probe, monkeypatch):
    """The first arm takes --base-model (--base-model-heavy), every effect on; the second
    --model (--model-heavy) with the withheld effects off, the --log channels logged and, with
    --state-yaw-calibration, the anemometer's yaw calibration stated; the records name each
    arm's model, logged channels and what it states."""
    import bayes_roadload.analysis.batch as batch
    import bayes_roadload.analysis.calibration as calibration

    calls = []

    def jobs(seeds, lo, hi, options=None, model=None, withhold=(), model_heavy=None, log=(),
             state_yaw_calibration=False):
        calls.append((model, model_heavy, tuple(withhold), tuple(log), state_yaw_calibration))
        return [model]

    monkeypatch.setattr(calibration, "calibration_jobs", jobs)
    monkeypatch.setattr(batch, "run_batch", lambda jobs, progress=True: pd.DataFrame({"name": ["ind-1"]}))
    records = probe.run([1], ["pitch"], 1, 2, model="m", model_heavy="mh", base_model="b", base_model_heavy="bh",
                        log=["humidity"], state_yaw_calibration=True)
    assert calls == [("b", "bh", (), (), False), ("m", "mh", ("pitch",), ("humidity",), True)]
    assert records["arm_model"].tolist() == ["b", "m"] and records["arm"].tolist() == ["all", "withheld"]
    assert records["arm_logged"].tolist() == ["", "humidity"]
    assert records["arm_stated"].tolist() == ["", "yaw calibration"]
    table = probe.summary(pd.concat([_records("all", [-4.0], names=("ind-1",)),
                                     _records("withheld", [-2.0], names=("ind-1",)).assign(
                                         arm_logged="humidity", arm_stated="yaw calibration")],
                                    ignore_index=True))
    assert "also logged: humidity" in table and "stated in vehicle.toml: yaw calibration" in table


def test_a_failed_fit_is_left_out_of_the_pairs_not_counted_as_held(probe):
    """A record with an error has no interval (in95 empty): its seed leaves both arms' counts."""
    first = _records("all", [-4.0, -2.0]).assign(CD0_in95=[True, float("nan")], CD0_sd=[0.01, float("nan")],
                                                  error=[None, "MAP failed"])
    second = _records("withheld", [-4.0, -2.0], arm_model="variant").assign(
        CD0_in95=[True, False], CD0_sd=[0.02, 0.05], error=[None, None])
    table = probe.summary(pd.concat([first, second], ignore_index=True))
    assert "| all | 1 of 1 | 1 of 1 | |" in table and "1 campaigns (ind-1)" in table


def test_categories_keep_the_seeds_whose_first_draw_is_of_them(probe):
    """The seeds kept are those whose campaign vehicle (the seed's first draw) is a truck, every
    other seed is left out; an unknown category is refused."""
    from bayes_roadload.simulate.independent import first_draws

    seeds = range(3000, 3016)
    kept = probe.of_categories(seeds, ["heavy_truck", "light_truck"])
    drawn = {s: first_draws(s)[0].category for s in seeds}
    assert kept == [s for s in seeds if drawn[s].endswith("_truck")]
    assert 0 < len(kept) < len(seeds)
    assert probe.of_categories(seeds) == list(seeds)
    with pytest.raises(SystemExit, match="unknown categories"):
        probe.of_categories(seeds, ["lorry"])
