"""Research studies built on :mod:`bayes_roadload`, kept outside the package (not in the wheel).

They reproduce and extend the thesis (Passmore 1990) and check the package's methods:
:mod:`.thesis_study` (tables 6.8 and 6.9), :mod:`.replay` (the track's test-to-test spreads),
:mod:`.calibration` (anemometer calibration, sections 4.7.3 and 6.6), :mod:`.proof_suite`
(the sim-to-real diagnosis on campaigns with a withheld effect), :mod:`.planning_report` (the
planning tables of chapter 8 and ``docs/planning.md``) and :mod:`.thesis_tables` (published
values they compare with).  Run by the scripts in ``benchmarks/`` and the notebooks; the package
never imports them.
"""
