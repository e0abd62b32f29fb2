"""What the command line shows and where it writes: --quiet / --verbose through logging,
third-party warnings kept out, a non-empty --out refused unless --force, units stated on the
command line, provenance in fit.json."""

import json
import logging
import warnings
from pathlib import Path

import pandas as pd
import pytest

from bayes_roadload import console
from bayes_roadload.cli import EXIT_BROKEN_PIPE, EXIT_REFUSED, OUT_MARKER, main


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("console") / "c14"
    assert main(["simulate", "--case", "14", "--pairs", "1", "--seed", "2", "--out", str(out), "--quiet"]) == 0
    return out


def lsq(campaign_dir, out, *extra):
    return main(["fit", str(campaign_dir), "--method", "lsq", "--model", "three_term", "--no-report",
                 "--out", str(out), *extra])


def test_quiet_prints_nothing_and_still_writes(campaign_dir, tmp_path, capsys):
    assert lsq(campaign_dir, tmp_path / "q", "--quiet") == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert (tmp_path / "q" / "summary.csv").is_file()
    assert lsq(campaign_dir, tmp_path / "n") == 0  # the default prints the table and the files
    assert "CD0" in capsys.readouterr().out


def test_quiet_and_verbose_together_are_refused(campaign_dir, tmp_path, capsys):
    assert lsq(campaign_dir, tmp_path / "o", "-q", "-v") == EXIT_REFUSED
    assert "--quiet and --verbose" in capsys.readouterr().err and not (tmp_path / "o").exists()


def test_a_non_empty_out_is_refused_unless_force(campaign_dir, tmp_path, capsys):
    out = tmp_path / "fit"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert lsq(campaign_dir, out) == EXIT_REFUSED
    err = capsys.readouterr().err
    assert "is not empty" in err and "--force" in err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]  # nothing written
    assert lsq(campaign_dir, out, "--force") == 0
    marker = json.loads((out / OUT_MARKER).read_text())
    assert "summary.csv" in marker["written"] and "notes.txt" not in marker["written"]
    assert marker["command_line"].startswith("bayes-roadload fit ") and "--force" in marker["command_line"]
    # an earlier output's files are removed by --force; the user's own file is kept
    (out / "stale.csv").write_text("x")
    marker["written"].append("stale.csv")
    (out / OUT_MARKER).write_text(json.dumps(marker))
    assert lsq(campaign_dir, out, "--force") == 0
    assert not (out / "stale.csv").exists() and (out / "notes.txt").read_text() == "mine"


def test_third_party_warnings_are_debug_and_ours_are_warnings():
    seen = []

    class Keep(logging.Handler):
        def emit(self, record):
            seen.append((record.levelno, record.getMessage()))

    console.configure("verbose")
    logger = logging.getLogger(console.PACKAGE_LOGGER)
    keep = Keep()
    logger.addHandler(keep)
    ours = str(Path(console.__file__).with_name("cli.py"))
    try:
        with console.routed_warnings():
            warnings.warn_explicit("the future is near", FutureWarning, "/venv/site-packages/arviz/stats.py", 1)
            warnings.warn_explicit("one pair only", UserWarning, ours, 1)
    finally:
        logger.removeHandler(keep)
        console.configure("normal")
    assert (logging.DEBUG, "warning: the future is near (stats.py:1)") in seen
    assert (logging.WARNING, "warning: one pair only") in seen


def test_progress_bars_only_on_a_terminal(monkeypatch):
    console.configure("normal")
    monkeypatch.setattr("sys.stderr.isatty", lambda: False, raising=False)
    assert console.progress_bars(True) is False
    console.configure("quiet")
    assert console.progress_bars(True) is False
    console.configure("normal")


def test_speed_unit_is_converted_and_recorded(campaign_dir, tmp_path, capsys):
    kph = tmp_path / "kph"
    kph.mkdir()
    runs = pd.read_csv(campaign_dir / "runs.csv")
    runs.assign(speed_mps=runs["speed_mps"] * 3.6).to_csv(kph / "runs.csv", index=False)
    (kph / "vehicle.toml").write_text((campaign_dir / "vehicle.toml").read_text())
    assert lsq(kph, tmp_path / "refused") == EXIT_REFUSED  # km/h in a m/s column: caught, nothing written
    assert "--speed-unit kph" in capsys.readouterr().err and not (tmp_path / "refused").exists()
    assert lsq(kph, tmp_path / "fit", "--speed-unit", "kph") == 0
    assert lsq(campaign_dir, tmp_path / "ref") == 0
    got, ref = (pd.read_csv(tmp_path / d / "summary.csv").set_index("parameter") for d in ("fit", "ref"))
    assert got.loc["CD0", "mean"] == pytest.approx(ref.loc["CD0", "mean"], rel=1e-6)
    prov = json.loads((tmp_path / "fit" / "fit.json").read_text())["provenance"]
    (conv,) = prov["conversions"]
    assert conv["column"] == "speed_mps" and conv["unit"] == "km/h" and conv["stated_by"] == "--speed-unit"
    assert len(prov["campaign_sha256"]) == 64 and prov["command_line"].endswith("--speed-unit kph")


def test_a_logged_humidity_lightens_the_air_and_fit_json_says_so(campaign_dir, tmp_path):
    """The same campaign with a ``relative_humidity_pct`` column: the least-squares fit sees the
    drag force through rho C_D, so C_D0 rises by the dry-to-moist density ratio and the rolling
    terms stay (but for the lift's share); ``fit.json`` records the air each fit took."""
    from bayes_roadload.physics.atmosphere import air_density_kgpm3

    moist = tmp_path / "moist"
    moist.mkdir()
    runs = pd.read_csv(campaign_dir / "runs.csv")
    runs.assign(relative_humidity_pct=70.0).to_csv(moist / "runs.csv", index=False)
    (moist / "vehicle.toml").write_text((campaign_dir / "vehicle.toml").read_text())
    assert lsq(moist, tmp_path / "fit") == 0 and lsq(campaign_dir, tmp_path / "ref") == 0
    got, ref = (pd.read_csv(tmp_path / d / "summary.csv").set_index("parameter") for d in ("fit", "ref"))
    t = runs["temperature_k"].mean() if "temperature_k" in runs else 293.2
    p = runs["pressure_pa"].mean() if "pressure_pa" in runs else 100_000.0
    ratio = air_density_kgpm3(p, t) / air_density_kgpm3(p, t, 0.70)
    assert ratio > 1.004   # the effect is resolved against the tolerances below
    # rho C_D is what the data fix: the optimum scales exactly, the optimiser's tolerance aside
    assert got.loc["CD0", "mean"] / ref.loc["CD0", "mean"] == pytest.approx(ratio, rel=1e-4)
    # the rolling terms move only through the tunnel lift that unloads the tyres (q_r A C_L: its
    # few per cent of the weight, 0.5 % lighter): by at most 0.05 x (ratio - 1) < 1e-3
    assert got.loc["AD", "mean"] == pytest.approx(ref.loc["AD", "mean"], rel=1e-3)
    amb, dry = (json.loads((tmp_path / d / "fit.json").read_text())["provenance"]["ambient"] for d in ("fit", "ref"))
    assert amb["air"] == "moist" and amb["relative_humidity_pct"] == pytest.approx(70.0)
    assert dry["air"] == "dry" and dry["relative_humidity_pct"] is None
    assert amb["air_density_kgpm3"] == pytest.approx(dry["air_density_kgpm3"] / ratio, rel=1e-6)


def test_the_command_line_fills_and_reuses_the_compilation_cache(campaign_dir, tmp_path):
    """Two processes fit the same campaign: the first writes compiled programs to
    $BAYES_ROADLOAD_CACHE_DIR, the second finds every program there and adds none."""
    import os
    import subprocess
    import sys

    cache = tmp_path / "cache"
    # every program cached (a threshold in compile seconds would make the count depend on the load)
    env = dict(os.environ, BAYES_ROADLOAD_CACHE_DIR=str(cache), BAYES_ROADLOAD_CACHE_DIR_MIN_COMPILE_S="0")

    def run(out):
        cmd = [sys.executable, "-m", "bayes_roadload", "fit", str(campaign_dir), "--method", "lsq", "--model",
               "three_term", "--no-report", "-q", "--out", str(tmp_path / out)]
        assert subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600).returncode == 0
        return sorted(p.name for p in cache.iterdir())

    first = run("a")
    assert first, "no compiled program was cached"
    assert run("b") == first


def test_a_reader_that_closes_the_pipe_ends_the_command_quietly(monkeypatch, capsys):
    """``bayes-roadload models | head -1``: the first line that finds the pipe closed ends the
    command with 141 (a shell's SIGPIPE code), with no "Logging error" per line on stderr."""
    import io

    class ClosedPipe(io.StringIO):
        lines = 0

        def write(self, text):
            ClosedPipe.lines += 1
            raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr("sys.stdout", ClosedPipe())
    assert main(["models"]) == EXIT_BROKEN_PIPE
    assert ClosedPipe.lines == 1
    assert capsys.readouterr().err == ""
