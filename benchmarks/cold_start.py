"""Cold and warm start of a fit from the shell prompt: ``bayes-roadload fit`` in a new process,
first with an empty persistent compilation cache (cold), then again with the cache the first run
filled (warm), then on another campaign of the same shapes (another seed of the simulator, its
runs padded to the same length) with that cache (warm, other campaign), timed from before the process starts to its exit, with the stages the fit records
in ``diagnostics.json`` (``stages_s``: imports, load, start values, fit setup, MAP, warm-up,
sampling, summaries and predictive, Type B, writing, report, compile, total).

The reference campaign is the issue's: 18 pairs (36 runs) from the independent simulator
(``bayes_roadload.simulate.independent``, calm wind, one vehicle category, fixed logging rate),
``--model four_term``, with the default ``--pooling auto`` (pooled at 36 runs) unless
``--pooling`` names others.  Records: ``benchmarks/records/performance/cold_start.json``; the section of
``docs/performance.md`` is generated from them (``--docs``).

    python benchmarks/cold_start.py [--pairs 18] [--rate-hz 4] [--pooling auto pooled] [--docs]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "records" / "performance" / "cold_start.json"
DOC = ROOT / "docs" / "performance.md"
BEGIN, END = "<!-- cold_start: begin -->", "<!-- cold_start: end -->"

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cli_process import run_cli  # noqa: E402
from doc_sections import replace_section  # noqa: E402
TARGETS_S = {"cold": 15.0, "warm": 8.0, "warm, other campaign": 8.0}


REFERENCE_SEED = 2026
"""Simulator seed of the reference campaign (cold and warm); the other campaign is the first later
seed whose runs pad to the same length (:func:`other_campaign`)."""


def campaign(pairs: int, root: Path, rate_hz: float, seed: int = 2026) -> tuple[Path, int]:
    """A reference campaign: the independent simulator, ``seed``, an SUV or van, calm wind,
    logged at ``rate_hz``; and the padded run length of its fit (``Campaign.to_batch``)."""
    sys.path.insert(0, str(ROOT))
    from bayes_roadload.data import save_campaign
    from bayes_roadload.simulate.independent import simulate_independent

    c = simulate_independent(seed, pairs=pairs, category="suv_van", wind="calm", sample_rate_hz=rate_hz)
    return save_campaign(c, root / f"ind_{pairs}pairs_{seed}"), int(c.to_batch()[0].time_s.shape[-1])


def other_campaign(pairs: int, root: Path, rate_hz: float, padded: int,
                   tries: int = 20) -> tuple[int, tuple[Path, int]] | None:
    """The first seed after :data:`REFERENCE_SEED` whose campaign pads to ``padded`` samples per
    run (the same shapes as the reference), and that campaign; None when none of ``tries`` seeds
    does (without ``BAYES_ROADLOAD_SHARE_PROGRAMS=1`` a campaign pads to its longest run, which
    rarely repeats)."""
    for seed in range(REFERENCE_SEED + 1, REFERENCE_SEED + 1 + tries):
        camp = campaign(pairs, root, rate_hz, seed)
        if camp[1] == padded:
            return seed, camp
    print(f"no seed of {tries} pads to {padded} samples per run: no 'warm, other campaign' row", flush=True)
    return None


def timed_fit(camp: Path, out: Path, cache: Path, pooling: str) -> dict:
    env = dict(os.environ, BAYES_ROADLOAD_CACHE_DIR=str(cache))
    wall, proc = run_cli(["fit", camp, "--model", "four_term", "--pooling", pooling, "--no-progress", "--no-report",
                          "--force", "--out", out], env=env, ok=None)
    diag = json.loads((out / "diagnostics.json").read_text()) if (out / "diagnostics.json").is_file() else {}
    return {"rc": proc.returncode, "wall_s": round(wall, 2), "stages_s": diag.get("stages_s", {}),
            "timings_s": diag.get("timings_s", {}), "pass": diag.get("pass"), "failed": diag.get("failed"),
            "retries": diag.get("retries", []), "pooling": diag.get("pooling") or pooling,
            "stderr_tail": proc.stderr.strip().splitlines()[-3:]}


def measure(pairs: int, poolings: list[str], rate_hz: float) -> dict:
    with tempfile.TemporaryDirectory(prefix="cold_start_") as tmp:
        tmp = Path(tmp)
        ref = campaign(pairs, tmp, rate_hz, REFERENCE_SEED)
        starts = {"cold": (REFERENCE_SEED, ref), "warm": (REFERENCE_SEED, ref)}
        other = other_campaign(pairs, tmp, rate_hz, ref[1])
        if other is not None:
            starts["warm, other campaign"] = other
        runs = sum(1 for _ in open(ref[0] / "runs.csv")) - 1
        rows = []
        for pooling in poolings:
            cache = tmp / f"cache_{pooling}"
            for start, (seed, (camp, padded)) in starts.items():
                r = timed_fit(camp, tmp / f"fit_{pooling}", cache, pooling)
                rows.append({"pooling": pooling, "start": start, "seed": seed, "padded_samples": padded, **r})
                print(json.dumps(rows[-1]), flush=True)
    return {"pairs": pairs, "runs": 2 * pairs, "samples": runs, "rate_hz": rate_hz, "model": "four_term",
            "cpu_count": os.cpu_count(),
            "load_1min": os.getloadavg()[0], "rows": rows}


def markdown(rec: dict) -> str:
    lines = ["", f"Reference: {rec['pairs']} pairs ({rec['runs']} runs, {rec['samples']} samples"
             f"{', logged at %g Hz' % rec['rate_hz'] if 'rate_hz' in rec else ''}) from the "
             "independent simulator, `fit --model four_term --no-progress --no-report` in a new process, timed "
             f"from the shell prompt to exit on this {rec['cpu_count']}-core machine (1-minute load "
             f"{rec['load_1min']:.1f} when the run ended). Cold: an empty compilation cache; warm: the cache the "
             "cold run filled (`BAYES_ROADLOAD_CACHE_DIR`, default `~/.cache/bayes-roadload/jax`)"
             + ("; warm, other campaign: another seed of the simulator, same runs and padded run length, with "
                "that cache (its programs are shared only with `BAYES_ROADLOAD_SHARE_PROGRAMS=1`, "
                "`bayes_roadload/_jax.py`)" if any(r["start"] == "warm, other campaign" for r in rec["rows"]) else "")
             + ". Stages from "
             "`diagnostics.json` `stages_s` (compilation is inside the stage that first runs a program, "
             "`warmup` holding the sampler's, and `compile` sums it over the whole command; start values (`start`) are the "
             "problem built and its least-squares start, which records without that column hold in "
             "`fit_setup`; after an R-hat or ESS miss "
             "the chains continue, and sampling includes the further draws (`extension_s`); after another "
             "failed gate, warm-up and sampling are the new run's and the first attempt's time is its own "
             "column).", "",
             "| pooling | start | seed (padded samples per run) | wall (s) | target | imports | load | start values | fit setup | MAP "
             "| first NUTS attempt | warm-up | sampling | summaries + predictive | Type B | writing | compile | gates |",
             "|" + "---|" * 18]
    for r in rec["rows"]:
        s, t = r["stages_s"], r["timings_s"]
        gates = "pass" if r["pass"] else f"FAIL ({', '.join(r['failed'] or [])})"
        if r["retries"]:
            gates += f", {len(r['retries'])} retry"
            if r["retries"][0].get("continued"):
                gates += f" (chains continued, {t['extension_s']:.1f} s)"
        seed = f"{r['seed']} ({r['padded_samples']})" if "seed" in r else "-"
        lines.append(f"| {r['pooling']} | {r['start']} | {seed} | {r['wall_s']:.1f} | <= {TARGETS_S[r['start']]:.0f} | "
                     f"{s.get('imports', 0):.1f} | {s.get('load', 0):.1f} | {_stage(s, 'start')} | "
                     f"{s.get('fit_setup', 0):.1f} | "
                     f"{t.get('map_s', 0):.1f} | "
                     f"{'%.1f' % t['first_attempt_s'] if 'first_attempt_s' in t else '-'} | "
                     f"{t.get('warmup_s', 0):.1f} | {t.get('sampling_s', 0):.1f} | "
                     f"{s.get('summaries_and_predictive', 0):.1f} | {s.get('type_b', 0):.1f} | "
                     f"{s.get('writing', 0):.1f} | {_stage(s, 'compile')} | {gates} |")
    return "\n".join(lines + ["", ""])


def _stage(stages: dict, name: str) -> str:
    """A stage's seconds, or '-' in a record written before the stage was timed."""
    return f"{stages[name]:.1f}" if name in stages else "-"


def write_doc(rec: dict) -> None:
    replace_section(DOC, BEGIN, END, markdown(rec), heading="## Cold and warm start")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=18)
    ap.add_argument("--pooling", nargs="+", default=["auto"])
    ap.add_argument("--rate-hz", type=float, default=4.0,
                    help="logging rate of the campaign (4 Hz: ~500 samples per run, as the issue's campaign)")
    ap.add_argument("--docs", action="store_true", help="regenerate the docs section from the records only")
    args = ap.parse_args()
    if not args.docs:
        rec = measure(args.pairs, args.pooling, args.rate_hz)
        RECORDS.parent.mkdir(parents=True, exist_ok=True)
        RECORDS.write_text(json.dumps(rec, indent=2) + "\n")
    write_doc(json.loads(RECORDS.read_text()))


if __name__ == "__main__":
    main()
