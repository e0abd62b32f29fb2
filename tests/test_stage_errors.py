"""A failure in a fit stage after the campaign was accepted names its stage (exit 4, one line,
the traceback in error.log)."""

import pytest

from bayes_roadload.cli import EXIT_FIT_FAILED, main


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("stages") / "c14"
    assert main(["simulate", "--case", "14", "--pairs", "1", "--seed", "1", "--out", str(out)]) == 0
    return out


def test_a_failure_while_sampling_or_writing_names_its_stage(campaign_dir, tmp_path, capsys, monkeypatch):
    """A failure inside NUTS (warm-up and sampling are one program) is reported as stage
    ``sampling`` and one written file's failure as stage ``output``: exit 4, one line with the
    stage and its remedy, the traceback in error.log and not on the terminal."""
    import numpyro.infer

    import bayes_roadload.output as output

    def broken_run(self, *a, **k):
        raise FloatingPointError("step size collapsed")

    monkeypatch.setattr(numpyro.infer.MCMC, "run", broken_run)
    out = tmp_path / "s"
    code = main(["fit", str(campaign_dir), "--model", "three_term", "--pooling", "pooled", "--warmup", "20",
                 "--draws", "20", "--chains", "1", "--no-progress", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == EXIT_FIT_FAILED
    assert "stage sampling" in err and "remedy" in err and "Traceback" not in err
    assert "step size collapsed" in (out / "error.log").read_text()

    def full_disk(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(output, "write_lsq_fit_dir", full_disk)
    out = tmp_path / "o"
    code = main(["fit", str(campaign_dir), "--method", "lsq", "--model", "three_term", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == EXIT_FIT_FAILED
    assert "stage output" in err and "--out is writable" in err and "Traceback" not in err
    assert "No space left on device" in (out / "error.log").read_text()
