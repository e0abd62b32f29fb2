"""The heavy-duty inputs of ``vehicle.toml``: the ``[cfr1037]`` table of 40 CFR 1037.528 (h)(5), (h)(6).

The regulation's drag area subtracts the drive-axle spin loss and the tyres' rolling resistance
between the high- and the low-speed range (:mod:`bayes_roadload.analysis.cfr1037`).  Both come
from bench tests, not from the coastdown, and a campaign may state them::

    [cfr1037]
    tyre_revolutions_per_mile = 508                  # TRPM of the drive tyres (1037.520(c)(1))
    axle_spin_loss_coefficients = [-206.841, 239.8279, 21.27505]
                # c0 (W), c1 (W s/r), c2 (W s^2/r^2): the drive axle's power loss against wheel
                # speed (r/s), second-order regression of the zero-torque points of 1037.560

    [[cfr1037.axle]]                                 # one per axle position: SAE J2452 regression
    position = "steer"
    tyres = 2
    pressure_kpa = 758.4                             # set and measured at the start of the test
    load_n = 51421.2                                 # load over the axle position
    alpha = -0.2435                                  # regression coefficients of J2452, fitted with
    beta = 0.9576                                    # the pressure in kPa, the load per tyre in N
    a = 0.0434                                       # and the speed in km/h
    b = 5.4e-5
    c = 5.53e-7

The spin-loss pair (``tyre_revolutions_per_mile`` and ``axle_spin_loss_coefficients``) comes
together or not at all; the axles may be given without it.  :func:`cfr1037_from_toml` refuses
anything else naming the file and the key; the campaign carries the table in
``meta["cfr1037"]``.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from .checks import refuse

CFR1037_TABLE = "cfr1037"
SPIN_KEYS = ("tyre_revolutions_per_mile", "axle_spin_loss_coefficients")
AXLE_KEYS = ("position", "tyres", "pressure_kpa", "load_n", "alpha", "beta", "a", "b", "c")
_RANGES = {"tyre_revolutions_per_mile": (100.0, 2000.0, "tyre revolutions per mile (truck tyres: about 500)"),
           "pressure_kpa": (50.0, 1500.0, "an inflation pressure in kPa"),
           "load_n": (100.0, 500000.0, "an axle load in N (not kg)")}


def _number(where: str, key: str, val) -> float:
    if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(float(val)):
        refuse(where, key, None, f"{val!r} is not a number")
    val = float(val)
    name = key.rsplit(" ", 1)[-1]
    if name in _RANGES:
        lo, hi, what = _RANGES[name]
        if not lo <= val <= hi:
            refuse(where, key, None, f"{val:g} is outside [{lo:g}, {hi:g}]: not {what}")
    return val


def cfr1037_from_toml(table: Mapping[str, Any], where: str) -> dict[str, Any]:
    """The validated ``[cfr1037]`` table (module docstring) as plain values: ``tyre_revolutions_per_mile``,
    ``axle_spin_loss_coefficients`` (c0, c1, c2) and ``axle`` (a list of per-position dicts),
    each only when given."""
    table = dict(table)
    for k in table:
        if k not in SPIN_KEYS + ("axle",):
            refuse(where, f"[{CFR1037_TABLE}] {k}", None, f"unknown key; known: {', '.join(SPIN_KEYS + ('axle',))}")
    out: dict[str, Any] = {}
    given = [k for k in SPIN_KEYS if k in table]
    if len(given) == 1:
        missing = next(k for k in SPIN_KEYS if k not in table)
        refuse(where, f"[{CFR1037_TABLE}] {missing}", None,
               f"needed with {given[0]}: the spin loss force is the axle's power loss at the wheel speed "
               "v x TRPM, divided by v (40 CFR 1037.528 (h)(5))")
    if given:
        out["tyre_revolutions_per_mile"] = _number(where, f"[{CFR1037_TABLE}] tyre_revolutions_per_mile",
                                                   table["tyre_revolutions_per_mile"])
        c = table["axle_spin_loss_coefficients"]
        if not isinstance(c, list) or len(c) != 3:
            refuse(where, f"[{CFR1037_TABLE}] axle_spin_loss_coefficients", None,
                   f"{c!r} is not three numbers [c0 (W), c1 (W s/r), c2 (W s^2/r^2)]")
        out["axle_spin_loss_coefficients"] = [_number(where, f"[{CFR1037_TABLE}] axle_spin_loss_coefficients", x)
                                              for x in c]
    if "axle" in table:
        axles = table["axle"]
        if not isinstance(axles, list) or not axles or not all(isinstance(a, dict) for a in axles):
            refuse(where, f"[[{CFR1037_TABLE}.axle]]", None, "give one [[cfr1037.axle]] table per axle position")
        out["axle"] = []
        for i, a in enumerate(axles, 1):
            here = f"[[{CFR1037_TABLE}.axle]] {i}"
            for k in a:
                if k not in AXLE_KEYS:
                    refuse(where, f"{here} {k}", None, f"unknown key; known: {', '.join(AXLE_KEYS)}")
            for k in AXLE_KEYS:
                if k not in a:
                    refuse(where, f"{here} {k}", None, "required key is missing")
            tyres = a["tyres"]
            if isinstance(tyres, bool) or not isinstance(tyres, int) or not 1 <= tyres <= 32:
                refuse(where, f"{here} tyres", None, f"{tyres!r} is not a whole number of tyres in [1, 32]")
            row = {"position": str(a["position"]), "tyres": int(tyres)}
            row.update({k: _number(where, f"{here} {k}", a[k]) for k in AXLE_KEYS[2:]})
            out["axle"].append(row)
    return out


def cfr1037_toml_lines(inputs: Mapping[str, Any] | None, toml_value) -> list[str]:
    """The ``[cfr1037]`` lines of ``vehicle.toml`` (``toml_value`` formats a value); none when
    there are no inputs."""
    if not inputs:
        return []
    lines = ["", f"[{CFR1037_TABLE}]"]
    lines += [f"{k} = {toml_value(inputs[k])}" for k in SPIN_KEYS if k in inputs]
    for a in inputs.get("axle", []):
        lines += ["", f"[[{CFR1037_TABLE}.axle]]"] + [f"{k} = {toml_value(a[k])}" for k in AXLE_KEYS]
    return lines
