"""The 19 simulation cases of thesis table 6.7."""

import pytest

from bayes_roadload.simulate import CASES, SimulationCase, get_case

# table 6.7: case -> (head, cross, dynamics, measurement noise, system noise, model)
TABLE_6_7 = {
    1: (1, 1, False, False, False, "basic"),
    2: (2, 2, False, False, False, "basic"),
    3: (3, 3, False, False, False, "basic"),
    4: (0, 2, False, False, False, "basic"),
    5: (0, 3, False, False, False, "basic"),
    6: (3, 3, False, False, False, "basic"),
    7: (2, 2, True, False, False, "basic"),
    8: (3, 3, True, False, False, "basic"),
    9: (2, 2, False, True, False, "basic"),
    10: (2, 2, False, False, True, "basic"),
    11: (2, 2, False, False, False, "comp"),
    12: (3, 3, False, False, False, "comp"),
    13: (2, 2, False, False, False, "table"),
    14: (2, 2, True, True, True, "comp"),
    15: (2, 2, True, True, True, "comp"),
    16: (3, 3, True, True, True, "comp"),
    17: (3, 3, True, True, True, "comp"),
    18: (0, 3, True, True, True, "comp"),
    19: (0, 3, True, True, True, "comp"),
}


def test_nineteen_presets_match_table_6_7():
    assert sorted(CASES) == list(range(1, 20))
    for n, (head, cross, dyn, meas, syst, model) in TABLE_6_7.items():
        c = get_case(n)
        assert c.number == n
        assert (c.head_wind_mps, c.cross_wind_mps) == (head, cross), n
        assert (c.dynamics, c.measurement_noise, c.system_noise, c.model) == (dyn, meas, syst, model), n
        # only case 6 has a spatial variation of the mean wind
        assert (c.spatial_beta > 0) == (n == 6), n


@pytest.mark.parametrize("bad", [0, 20, -1, "3", 2.0, True, None])
def test_unknown_case_is_refused(bad):
    with pytest.raises(KeyError, match="unknown simulation case"):
        get_case(bad)


def test_custom_case_validation():
    c = SimulationCase(99, "custom", 1.5, 0.5, dynamics=True, model="comp", spatial_beta=0.2)
    assert c.model == "comp"
    with pytest.raises(ValueError):
        SimulationCase(98, "bad model", 1.0, 1.0, model="exotic")
    with pytest.raises(ValueError):
        SimulationCase(97, "negative wind", -1.0, 1.0)
    with pytest.raises(Exception):
        c.number = 3  # frozen
