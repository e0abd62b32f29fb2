"""Stage errors: the message names the stage, the run or parameter and the remedy; the
traceback goes to error.log."""

import pytest

from bayes_roadload.errors import ERROR_LOG, FitStageError, stage, write_error_log


def test_stage_names_the_stage_and_keeps_the_cause():
    with pytest.raises(FitStageError) as err:
        with stage("map", parameter="AD"):
            raise ValueError("array must not contain infs or NaNs")
    e = err.value
    assert e.stage == "map" and e.parameter == "AD" and isinstance(e.__cause__, ValueError)
    assert str(e).startswith("stage map, parameter AD: ValueError: array must not contain infs or NaNs; remedy: ")


def test_refused_input_passes_the_load_stage_unchanged():
    with pytest.raises(FileNotFoundError):
        with stage("load"):
            raise FileNotFoundError("runs.csv")
    with pytest.raises(FitStageError):  # the same error in a later stage is a failure of that stage
        with stage("output"):
            raise FileNotFoundError("posterior.nc")


def test_unknown_stage_is_refused():
    with pytest.raises(ValueError, match="unknown fit stage"):
        FitStageError("plotting", "x")


def test_error_log_holds_the_chained_traceback(tmp_path):
    try:
        with stage("sampling", run=3):
            raise ZeroDivisionError("step size")
    except FitStageError as e:
        path = write_error_log(tmp_path / "out", e, argv=["fit", "camp"])
    text = path.read_text()
    assert path.name == ERROR_LOG and "bayes-roadload fit camp" in text
    assert "ZeroDivisionError: step size" in text and "FitStageError: stage sampling, run 3" in text
    assert write_error_log(None, ValueError("x")) is None
