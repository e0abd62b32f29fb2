"""The report of a fit (bayes_roadload.output.report): sections by what a fit directory holds,
numbers equal to summary.csv, images that decode, and the page in a headless browser."""

import base64
import io
import json
import math
import shutil
import tempfile
import warnings
from html.parser import HTMLParser
from pathlib import Path

import arviz as az
import matplotlib.image
import numpy as np
import pandas as pd
import pytest

from bayes_roadload.cli import main as cli
from bayes_roadload.data import save_campaign
from bayes_roadload.inference.results import REMEDIES
from bayes_roadload.output.report import FILES_DIR, fmt, render_report
from bayes_roadload.simulate import simulate_campaign
from bayes_roadload.simulate.intervals import interval_campaign_from_traces
from bayes_roadload.simulate.spindown import simulate_spindown

from ..conftest import clean_case

SMALL = ["--warmup", "200", "--draws", "200", "--chains", "2", "--no-progress"]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# summary.csv numbers are printed to 5 significant digits: the printed value differs from the
# file's by at most half a unit in the 5th digit, i.e. a relative 5e-5 of the value
PRINT_RTOL = 5e-5


class _Page(HTMLParser):
    """Sections (id -> their tables as lists of rows of cell text), image sources, alert texts
    and the position of each section and alert in the page."""

    def __init__(self):
        super().__init__()
        self.sections, self.images, self.alerts, self.order = {}, [], [], []
        self._section = None
        self._row = self._cell = None
        self._alert = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "section":
            self._section = a["id"]
            self.sections[self._section] = []
            self.order.append(("section", self._section))
        elif tag == "table":
            self.sections[self._section].append([])
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = ""
        elif tag == "img":
            self.images.append(a["src"])
        elif tag == "p" and a.get("class") == "alert":
            self._alert = ""

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self._row.append(self._cell)
            self._cell = None
        elif tag == "tr":
            self.sections[self._section][-1].append(self._row)
        elif tag == "p" and self._alert is not None:
            self.alerts.append(self._alert)
            self.order.append(("alert", self._alert))
            self._alert = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data
        if self._alert is not None:
            self._alert += data


def parse(html_path: Path) -> _Page:
    page = _Page()
    page.feed(html_path.read_text(encoding="utf-8"))
    return page


def _fit(tmp: Path, campaign, name: str, *extra: str) -> Path:
    root = save_campaign(campaign, tmp / f"{name}_campaign")
    out = tmp / name
    rc = cli(["fit", str(root), *extra, "--out", str(out)])
    assert rc in (0, 3)  # 3: the gates failed (small draws); the report shows that too
    return out


@pytest.fixture(scope="module")
def fits(tmp_path_factory, cli_nuts_fit):
    """Fit directories of three kinds: speed traces by NUTS (the run's shared command-line fit,
    ``tests/conftest.py``) and by least squares, interval times."""
    tmp = tmp_path_factory.mktemp("report")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traces = simulate_campaign(clean_case(), pairs=1, seed=21)
        intervals = interval_campaign_from_traces(simulate_campaign(clean_case(), pairs=2, seed=22))
        dirs = {"nuts": cli_nuts_fit.fit_dir,
                "lsq": _fit(tmp, traces, "lsq", "--method", "lsq"),
                "intervals": _fit(tmp, intervals, "intervals", "--no-type-b", *SMALL)}   # budget: the "nuts" fit
    return dirs  # `fit` renders each report


def test_sections_follow_the_files(fits):
    expected = {
        "nuts": {"header", "gates", "posterior", "trace", "pairs", "road-load", "residuals", "table-runs-summary",
                 "table-budget"},
        "lsq": {"header", "gates", "posterior", "road-load", "table-per-group"},
        "intervals": {"header", "gates", "posterior", "trace", "pairs", "road-load", "residuals", "validity",
                      "table-runs-summary"},
    }
    for kind, d in fits.items():
        page = parse(d / "report.html")
        assert set(page.sections) == expected[kind], kind
        assert [s for t, s in page.order if t == "section"][:3] == ["header", "gates", "posterior"]


def _posterior_rows(page: _Page) -> dict[str, dict[str, str]]:
    (table,) = page.sections["posterior"]
    header = table[0]
    return {row[0]: dict(zip(header, row)) for row in table[1:]}


@pytest.mark.parametrize("kind", ["nuts", "lsq", "intervals"])
def test_every_number_equals_summary_csv(fits, kind):
    summary = pd.read_csv(fits[kind] / "summary.csv")
    rows = _posterior_rows(parse(fits[kind] / "report.html"))
    assert list(rows) == list(summary["parameter"])
    for _, r in summary.iterrows():
        shown = rows[r["parameter"]]
        for col in ("mean", "sd", "q2.5", "q97.5"):
            assert shown[col] == fmt(r[col])
            assert math.isclose(float(shown[col]), r[col], rel_tol=PRINT_RTOL, abs_tol=1e-300)


def test_truth_column_from_the_campaign(fits):
    rows = _posterior_rows(parse(fits["nuts"] / "report.html"))
    truth = json.loads((Path(json.loads((fits["nuts"] / "fit.json").read_text())["campaign"])
                        / "truth.json").read_text())
    for p in ("AD", "BD", "CD0", "KD"):
        assert float(rows[p]["truth"]) == pytest.approx(truth[p], rel=PRINT_RTOL)
        inside = float(rows[p]["q2.5"]) <= truth[p] <= float(rows[p]["q97.5"])
        assert rows[p]["in 95 %"] in ("yes", "NO") and (rows[p]["in 95 %"] == "yes") == inside


@pytest.mark.parametrize("kind", ["nuts", "lsq", "intervals"])
def test_images_are_embedded_png_and_written_for_markdown(fits, kind):
    d = fits[kind]
    page = parse(d / "report.html")
    md = (d / "report.md").read_text()
    files = sorted((d / FILES_DIR).glob("*.png"))
    assert page.images and len(page.images) == len(files)
    for src in page.images:
        assert src.startswith("data:image/png;base64,")
        png = base64.b64decode(src.split(",", 1)[1], validate=True)
        assert png.startswith(PNG_SIGNATURE)
        h, w = matplotlib.image.imread(io.BytesIO(png)).shape[:2]
        assert h > 50 and w > 50
        assert any(f.read_bytes() == png for f in files)
    for f in files:
        assert f"]({FILES_DIR}/{f.name})" in md


def test_residuals_per_run(fits):
    page = parse(fits["intervals"] / "report.html")
    assert any("Residuals" in f for f in (fits["intervals"] / "report.md").read_text().splitlines())
    assert (fits["intervals"] / FILES_DIR / "residuals_interval_s.png").is_file()
    assert (fits["nuts"] / FILES_DIR / "residuals_speed_mps.png").is_file()
    validity = pd.read_csv(fits["intervals"] / "validity.csv")
    (table,) = page.sections["validity"]
    assert [row[0] for row in table[1:]] == [str(r) for r in validity["run"]]


def test_road_load_table_brackets_the_classical_curve_for_lsq(fits):
    """The least-squares report draws F = F0 + F1 v + F2 v^2 of its weighted mean; the table's
    classical column at each reference speed equals that polynomial."""
    s = pd.read_csv(fits["lsq"] / "summary.csv").set_index("parameter")["mean"]
    (table,) = parse(fits["lsq"] / "report.html").sections["road-load"]
    header = table[0]
    assert header == ["speed_kph", "classical_N"]
    for row in table[1:]:
        v = float(row[0])
        expected = s["F0_N"] + s["F1_N_per_kph"] * v + s["F2_N_per_kph2"] * v**2
        assert float(row[1]) == pytest.approx(expected, rel=PRINT_RTOL)


def test_failed_gate_opens_the_report_with_its_remedy(fits, tmp_path):
    d = tmp_path / "failed"
    shutil.copytree(fits["nuts"], d)
    diag = json.loads((d / "diagnostics.json").read_text())
    diag["gates"] = {k: True for k in diag["gates"]} | {"divergences": False}
    diag["failed"], diag["pass"] = ["divergences"], False
    (d / "diagnostics.json").write_text(json.dumps(diag))
    fit = json.loads((d / "fit.json").read_text())
    fit["campaign"] = str(tmp_path / "moved_away")  # the campaign is gone: no truth column, still a report
    (d / "fit.json").write_text(json.dumps(fit))
    page = parse(render_report(d)[0])
    first_alert = next(i for i, (t, _) in enumerate(page.order) if t == "alert")
    assert page.order.index(("section", "gates")) < first_alert < page.order.index(("section", "posterior"))
    assert "divergences" in page.alerts[0]
    (gates,) = page.sections["gates"]
    row = next(r for r in gates if r[0] == "divergences")
    assert row[3] == "FAIL" and row[4] == REMEDIES["divergences"]
    assert "truth" not in _posterior_rows(page)["CD0"]


def test_passing_gates_show_no_alert(fits, tmp_path):
    d = tmp_path / "passed"
    shutil.copytree(fits["nuts"], d)
    diag = json.loads((d / "diagnostics.json").read_text())
    diag["gates"] = {k: True for k in diag["gates"]}
    diag["failed"], diag["pass"], diag["map_converged"] = [], True, True
    (d / "diagnostics.json").write_text(json.dumps(diag))
    page = parse(render_report(d)[0])
    assert page.alerts == []
    (gates,) = page.sections["gates"]
    assert [r[3] for r in gates[1:]] == ["PASS"] * len(diag["gates"])


def test_refuses_a_directory_without_summary(tmp_path):
    with pytest.raises(FileNotFoundError, match="summary.csv"):
        render_report(tmp_path)


def _summary_of(draws: dict) -> pd.DataFrame:
    rows = []
    for k, x in draws.items():
        q = np.percentile(x, [2.5, 50.0, 97.5])
        rows.append({"parameter": k, "mean": x.mean(), "sd": x.std(ddof=1), "q2.5": q[0], "q50": q[1],
                     "q97.5": q[2], "r_hat": 1.0, "ess_bulk": 400.0, "ess_tail": 400.0})
    return pd.DataFrame(rows)


def test_channel_fit_without_predictive(tmp_path):
    """A fit directory as a spin-down writes it (Au, Bu draws, classical.csv with a ``total`` row,
    no posterior predictive, fit.json naming a spin-down campaign whose vehicle.toml describes
    wheels, not a vehicle): the curve Au + Bu v (v in m/s) with its bands beside the classical
    line, a pair plot Au-Bu, and a note instead of residuals."""
    campaign = save_campaign(simulate_spindown(tests_per_wheel=1, seed=2), tmp_path / "campaign")
    tmp_path = tmp_path / "fit"
    tmp_path.mkdir()
    (tmp_path / "fit.json").write_text(json.dumps({"kind": "spindown", "model": "undriven_spindown",
                                                   "campaign": str(campaign)}))
    rng = np.random.default_rng(5)
    draws = {"Au": rng.normal(3.2, 0.1, (2, 300)), "Bu": rng.normal(0.23, 0.01, (2, 300))}
    az.from_dict(posterior=draws).to_netcdf(str(tmp_path / "posterior.nc"))
    _summary_of({k: v.ravel() for k, v in draws.items()}).to_csv(tmp_path / "summary.csv", index=False)
    (tmp_path / "diagnostics.json").write_text(json.dumps(
        {"kind": "spindown", "model": "undriven_spindown", "chains": 2, "draws_per_chain": 300,
         "gates": {"divergences": True}, "failed": [], "pass": True, "divergences": 0,
         "thresholds": {"max_divergences": 0}}))
    classical = pd.DataFrame({"wheel": ["front_left", "total"], "Au": [1.6, 3.1], "Au_se": [0.1, 0.1],
                              "Bu": [0.12, 0.24], "Bu_se": [0.01, 0.01]})
    classical.to_csv(tmp_path / "classical.csv", index=False)
    page = parse(render_report(tmp_path)[0])
    assert set(page.sections) == {"header", "gates", "posterior", "trace", "pairs", "road-load", "residuals",
                                  "table-classical"}
    assert (tmp_path / FILES_DIR / "pair_Au_Bu.png").is_file()
    assert "no posterior predictive" in (tmp_path / "report.md").read_text()
    (table,) = page.sections["road-load"]
    assert table[0] == ["speed_kph", "posterior_q2.5_N", "posterior_q50_N", "posterior_q97.5_N", "classical_N"]
    for row in table[1:]:
        w = float(row[0]) / 3.6  # km/h -> m/s
        curve = draws["Au"].ravel() + draws["Bu"].ravel() * w
        for cell, q in zip(row[1:4], np.percentile(curve, [2.5, 50.0, 97.5])):
            assert float(cell) == pytest.approx(q, rel=PRINT_RTOL)
        assert float(row[4]) == pytest.approx(3.1 + 0.24 * w, rel=PRINT_RTOL)


# ----------------------------------------------------------------------------- headless browser

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")


def _browser():
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        pytest.skip("selenium is not installed (pip install '.[test]')")
    if not CHROMIUM or not CHROMEDRIVER:
        pytest.skip("no Chromium / chromedriver on PATH (Debian: apt-get install chromium chromium-driver)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="report-chromium-")
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", f"--user-data-dir={profile}"):
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=opts), profile


@pytest.mark.parametrize("kind", ["nuts", "intervals"])
def test_page_in_a_headless_browser(fits, kind):
    from selenium.webdriver.common.by import By

    driver, profile = _browser()
    try:
        driver.get((fits[kind] / "report.html").resolve().as_uri())
        severe = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        assert severe == []
        images = driver.find_elements(By.TAG_NAME, "img")
        assert len(images) == len(list((fits[kind] / FILES_DIR).glob("*.png")))
        for img in images:
            assert driver.execute_script("return arguments[0].complete && arguments[0].naturalWidth", img) > 0
        summary = pd.read_csv(fits[kind] / "summary.csv").set_index("parameter")
        rows = driver.find_elements(By.CSS_SELECTOR, "#posterior tbody tr")
        shown = {r.find_elements(By.TAG_NAME, "td")[0].text: r.find_elements(By.TAG_NAME, "td")[1].text
                 for r in rows}
        assert shown["CD0"] == fmt(summary.loc["CD0", "mean"])
        assert math.isclose(float(shown["CD0"]), summary.loc["CD0", "mean"], rel_tol=PRINT_RTOL)
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


SPLIT = (Path(__file__).resolve().parents[3] / "shared" / "data" / "external" / "coastdown-mda-split"
         / "sample_data" / "Split" / "coastdown")


@pytest.mark.slow  # the browser check of test_page_in_a_headless_browser on a real campaign, ~30 s
@pytest.mark.external
@pytest.mark.skipif(not SPLIT.is_dir(), reason=f"{SPLIT} not present (real data are read in place)")
def test_report_of_a_real_interval_campaign_in_a_headless_browser(tmp_path):
    """A real VBOX split export (the Ioniq's high and low windows) imported and fitted through
    the command line: its report loads without console errors, every image renders, and the
    page's F0 equals summary.csv's."""
    from selenium.webdriver.common.by import By

    (tmp_path / "vehicle.toml").write_text("[vehicle]\nmass_kg = 1600.0\neffective_mass_kg = 1640.0\n"
                                           "frontal_area_m2 = 2.2\n")
    camp, out = tmp_path / "ioniq", tmp_path / "fit"
    assert cli(["import-vbox", str(SPLIT / "altas_ioniq.csv"), str(SPLIT / "baixas_ioniq.csv"), "--vehicle",
                str(tmp_path / "vehicle.toml"), "--out", str(camp), "-q"]) == 0
    assert cli(["fit", str(camp), *SMALL, "--no-type-b", "--out", str(out), "-q"]) in (0, 3)
    summary = pd.read_csv(out / "summary.csv").set_index("parameter")
    driver, profile = _browser()
    try:
        driver.get((out / "report.html").resolve().as_uri())
        assert [e for e in driver.get_log("browser") if e["level"] == "SEVERE"] == []
        images = driver.find_elements(By.TAG_NAME, "img")
        assert images and len(images) == len(list((out / FILES_DIR).glob("*.png")))
        for img in images:
            assert driver.execute_script("return arguments[0].complete && arguments[0].naturalWidth", img) > 0
        rows = driver.find_elements(By.CSS_SELECTOR, "#posterior tbody tr")
        shown = {r.find_elements(By.TAG_NAME, "td")[0].text: r.find_elements(By.TAG_NAME, "td")[1].text for r in rows}
        assert math.isclose(float(shown["F0_N"]), summary.loc["F0_N", "mean"], rel_tol=PRINT_RTOL)
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def test_the_budget_figure_draws_every_source_s_share():
    """Two quantities, seven sources: the data's share, the five sources with the largest share
    of either quantity, the other two together; each quantity's parts add up to its whole
    variance, and the row of a source left out (no quantity) is not drawn."""
    from bayes_roadload.output.report import BUDGET_SOURCES_SHOWN, budget_figure, budget_parts

    share = {"AD": {"data": 0.1, "s1": 0.5, "s2": 0.2, "s3": 0.1, "s4": 0.05, "s5": 0.03, "s6": 0.02},
             "CD0": {"data": 0.3, "s7": 0.6, "s1": 0.1}}
    rows = [{"quantity": q, "source": s, "variance_share": v} for q, d in share.items() for s, v in d.items()]
    rows.append({"quantity": "", "source": "left_out", "variance_share": float("nan")})
    budget = pd.DataFrame(rows)
    quantities, parts = budget_parts(budget)
    assert quantities == ["AD", "CD0"]
    labels = [label for label, _ in parts]
    assert BUDGET_SOURCES_SHOWN == 5 and labels == ["data (the posterior's own)", "s7", "s1", "s2", "s3", "s4",
                                                    "2 other sources"]
    np.testing.assert_allclose(sum(v for _, v in parts), [1.0, 1.0])
    np.testing.assert_allclose(dict(parts)["2 other sources"], [0.05, 0.0])
    assert budget_figure(budget).png.startswith(PNG_SIGNATURE)
    assert budget_figure(budget[budget["quantity"] == ""]) is None


def test_the_budget_section_opens_with_its_figure(fits):
    """The NUTS fit's budget.csv is drawn in its own section, before its table."""
    assert (fits["nuts"] / FILES_DIR / "budget.png").is_file()
    md = (fits["nuts"] / "report.md").read_text()
    section = md[md.index("Uncertainty budget (budget.csv)"):]
    assert section.index(f"]({FILES_DIR}/budget.png)") < section.index("| quantity |")
