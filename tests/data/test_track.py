"""The track survey (track.csv): round trip, the grade it puts on each logged position, the model
term it adds, and every refusal names file/column/row."""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayes_roadload.data import Campaign, CampaignError, Vehicle, load_campaign, save_campaign
from bayes_roadload.data.io import DATA_KINDS
from bayes_roadload.data.track import MAX_GRADE, grade_at, segment_grades
from bayes_roadload.inference.spec import load_model_spec

from .test_traces import VEHICLE_TOML, runs_frame, write

SLOPE = 0.001   # a rise of 1 m per km: 0.1 % grade
MODELS = Path(__file__).resolve().parents[2] / "models"


def runs_with_position(n=40):
    """Two runs over 0-300 m of the track, the second back the way the first came."""
    df = runs_frame(n)
    t = df["time_s"].to_numpy()
    travelled = 30.0 * t - 0.15 * t**2
    df["position_m"] = np.where(df["direction"] > 0, travelled, 300.0 - travelled)
    return df


def survey(slope=SLOPE, start=-50.0, end=400.0, spacing=10.0):
    x = np.arange(start, end + spacing, spacing)
    return pd.DataFrame({"position_m": x, "elevation_m": 12.0 + slope * x})


def test_round_trip_and_the_grade_channel(tmp_path):
    c = Campaign(runs_with_position(), Vehicle(1100.0, 1130.0, 1.85), track=survey())
    out = save_campaign(c, tmp_path / "c")
    assert (out / "track.csv").exists()
    back = load_campaign(out)
    assert back.has_track_survey
    pd.testing.assert_frame_equal(back.track, c.track)
    batch, _ = back.to_batch()
    np.testing.assert_allclose(np.asarray(batch.track_grade_rad), np.arctan(SLOPE), rtol=1e-12)


def test_no_survey_no_grade_and_a_stale_survey_is_removed(tmp_path):
    out = save_campaign(Campaign(runs_with_position(), Vehicle(1100.0, 1130.0, 1.85), track=survey()), tmp_path / "c")
    save_campaign(Campaign(runs_with_position(), Vehicle(1100.0, 1130.0, 1.85)), out)
    back = load_campaign(out)
    assert not (out / "track.csv").exists() and not back.has_track_survey
    batch, _ = back.to_batch()
    assert not np.asarray(batch.track_grade_rad).any()


def test_grade_between_segment_middles():
    """Each segment's rise over run sits at its middle; between middles the grade is linear."""
    track = pd.DataFrame({"position_m": [0.0, 10.0, 20.0], "elevation_m": [0.0, 0.01, 0.0]})
    middle, theta = segment_grades(track)
    np.testing.assert_allclose(middle, [5.0, 15.0])
    np.testing.assert_allclose(theta, np.arctan([0.001, -0.001]))
    np.testing.assert_allclose(grade_at(track, [0.0, 5.0, 10.0, 15.0, 20.0]),
                               np.arctan([0.001, 0.001, 0.0, -0.001, -0.001]), atol=1e-15)


def test_the_model_adds_the_surveyed_gradient_only_with_a_survey():
    spec = load_model_spec("four_term")
    with_survey = Campaign(runs_with_position(), Vehicle(1100.0, 1130.0, 1.85), track=survey())
    model, _, _ = spec.build(with_survey)
    assert "surveyed_gradient" in model.term_names
    model, _, _ = spec.build(Campaign(runs_with_position(), Vehicle(1100.0, 1130.0, 1.85)))
    assert "surveyed_gradient" not in model.term_names


def test_subset_keeps_the_survey():
    c = Campaign(runs_with_position(), Vehicle(1100.0, 1130.0, 1.85), track=survey())
    assert c.subset([2]).has_track_survey


@pytest.mark.parametrize(
    "track, expected, file",
    [
        (survey().rename(columns={"elevation_m": "elevation"}), "column 'elevation': unknown column; did you mean elevation_m", "track.csv"),
        (survey().drop(columns="elevation_m"), "column 'elevation_m': required column is missing", "track.csv"),
        (survey().iloc[:1], "1 station; a survey needs at least 2", "track.csv"),
        (survey().assign(position_m=lambda d: d["position_m"].where(d.index != 4, 5.0)),
         "column 'position_m', row 6: position 0 m does not increase on the station before it (5 m)", "track.csv"),
        (survey().assign(elevation_m=lambda d: d["elevation_m"].where(d.index != 7, np.nan)),
         "column 'elevation_m', row 8: an empty cell", "track.csv"),
        (survey(slope=1000 * SLOPE * 0.06), f"steeper than {100 * MAX_GRADE:g} %", "track.csv"),
        (survey(start=10.0), "row 1: run 1 at 0 m, outside the surveyed stretch 10 to 400 m", "runs.csv"),
    ],
)
def test_refusals_name_file_column_row(tmp_path, track, expected, file):
    d = write(tmp_path, runs_with_position(), VEHICLE_TOML)
    track.to_csv(d / "track.csv", index=False)
    with pytest.raises(CampaignError) as e:
        load_campaign(d)
    assert expected in str(e.value)
    assert str(e.value).startswith(str(d / file)), str(e.value)


def test_a_survey_needs_the_runs_positions(tmp_path):
    d = write(tmp_path, runs_frame(), VEHICLE_TOML)
    survey().to_csv(d / "track.csv", index=False)
    with pytest.raises(CampaignError, match="runs.csv, column 'position_m': track.csv surveys the track"):
        load_campaign(d)


def test_every_type_b_source_applies_to_a_survey_that_ends_where_the_runs_end():
    """A survey covering exactly the logged stretch stays valid under every Type B shift: the
    speed sensor's scale error moves the speeds and the distance travelled, not the position
    along the track (a GNSS or surveyed coordinate), so the grade read at it is unchanged."""
    from bayes_roadload.data.uncertainty import SOURCES

    runs = runs_with_position()
    c = Campaign(runs, Vehicle(1100.0, 1130.0, 1.85),
                 track=survey(start=float(runs["position_m"].min()), end=float(runs["position_m"].max()),
                              spacing=float(runs["position_m"].max() - runs["position_m"].min()) / 20))
    for name, source in SOURCES.items():
        shifted = source.apply(c, 3 * source.default)
        assert shifted is None or shifted.has_track_survey, name
    s = SOURCES["speed_scale_rel"].apply(c, 0.01)
    pd.testing.assert_series_equal(s.runs["position_m"], c.runs["position_m"])
    np.testing.assert_array_equal(np.asarray(s.to_batch()[0].track_grade_rad), np.asarray(c.to_batch()[0].track_grade_rad))


def test_fit_says_which_grade_it_reads():
    """The speed-trace kind's input notes (printed after the table of NUTS and of least squares)
    name the survey and its RMS grade at the logged positions (here the constant 0.1 %), say the
    grade is left out when the runs log positions without a survey and the model has no grade
    term of its own, and say nothing of it when they log none."""
    from bayes_roadload.inference.kinds import KINDS

    def notes(campaign, spec):  # the grade's notes (the speed coverage's are tested in test_cli)
        return [line for line in KINDS["traces"].input_notes(campaign, spec) if "F50_N" not in line]

    spec = load_model_spec("four_term")
    surveyed = notes(Campaign(runs_with_position(), Vehicle(1100.0, 1130.0, 1.85), track=survey()), spec)
    assert len(surveyed) == 1 and "46 stations over -50 to 400 m, RMS grade 0.100 %" in surveyed[0]
    unsurveyed = Campaign(runs_with_position(), Vehicle(1100.0, 1130.0, 1.85))
    assert "not in the model" in notes(unsurveyed, spec)[0]
    graded = dataclasses.replace(spec, terms=(*spec.terms, "gradient"))
    assert notes(unsurveyed, graded) == []
    assert notes(Campaign(runs_frame(), Vehicle(1100.0, 1130.0, 1.85)), spec) == []


def test_lsq_prints_the_survey(tmp_path, capsys):
    """``fit --method lsq`` prints the survey line after its table, as the NUTS fit does."""
    from bayes_roadload.cli import main

    c = Campaign(runs_with_position(), Vehicle(1100.0, 1130.0, 1.85), track=survey())
    d = save_campaign(c, tmp_path / "c")
    assert main(["fit", str(d), "--method", "lsq", "--model", "three_term", "--no-report", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "track survey: 46 stations" in out
    assert out.index("track survey:") > out.index("AD")


@pytest.mark.parametrize("column", [True, False])
def test_a_run_whose_direction_disagrees_with_its_positions_is_refused(tmp_path, column):
    """With a survey the grade's sign in a run is d theta(x), d = +1 where position_m
    increases: a run coded +1 whose position decreases (or every run +1 when the direction
    column is absent) would take the other direction's grade, and is refused at its first row."""
    df = runs_with_position()
    back = df["direction"] < 0
    first_back = int(np.flatnonzero(back.to_numpy())[0]) + 1
    if column:
        df.loc[back, "direction"] = 1
        expected = f"column 'direction', row {first_back}: run 2 has direction +1 but its position_m decreases"
    else:
        df = df.drop(columns="direction")
        expected = f"column 'position_m', row {first_back}: run 2's position_m decreases"
    d = write(tmp_path, df, VEHICLE_TOML)
    survey().to_csv(d / "track.csv", index=False)
    with pytest.raises(CampaignError) as e:
        load_campaign(d)
    assert expected in str(e.value) and "runs.csv" in str(e.value)
    with pytest.raises(CampaignError, match=re.escape(expected.split(": ", 1)[1])):
        Campaign(df, Vehicle(1100.0, 1130.0, 1.85), track=survey())


def test_a_model_file_may_not_list_the_surveyed_gradient(tmp_path):
    """The term reads the survey's channel; listed in a model file without a survey it would
    add a zero force silently, so the spec refuses it (the survey adds it)."""
    from bayes_roadload.inference.spec import ModelSpecError

    text = (MODELS / "four_term.toml").read_text()
    path = tmp_path / "graded.toml"
    path.write_text(text.replace('terms = [', 'terms = ["surveyed_gradient", ', 1))
    with pytest.raises(ModelSpecError, match="'surveyed_gradient' is added by the campaign's track survey"):
        load_model_spec(path)


@pytest.mark.parametrize("kind", [k for k in DATA_KINDS if "track.csv" not in k.OPTIONAL_FILES], ids=lambda k: k.KIND)
def test_other_kinds_refuse_a_survey_beside_their_data(tmp_path, kind):
    """Only speed traces read track.csv; another kind's directory holding one is refused (its
    grade would be silently ignored), naming the file."""
    from .test_io import CAMPAIGNS

    src = save_campaign(CAMPAIGNS[kind.KIND](), tmp_path / "c")
    survey().to_csv(src / "track.csv", index=False)
    with pytest.raises(CampaignError, match=rf"track.csv: read with speed traces \(runs.csv, runs.parquet\) only; "
                                            rf"the {kind.DESCRIPTION} of"):
        load_campaign(src)
    assert not (save_campaign(CAMPAIGNS[kind.KIND](), src) / "track.csv").exists()  # saving removes it
