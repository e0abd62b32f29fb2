"""Published values of Passmore (1990), used for comparison and by the simulator's cases.

The thesis' test vehicle (tables 6.3-6.6), its coefficients and those of its full drag model,
its driveline and undriven-wheel losses (tables 7.8-7.10), the summary of its initial study
(table 7.11), its wind-tunnel table and the inputs of its simulation study (tables 6.4-6.6).
:mod:`bayes_roadload.simulate` simulates this vehicle when asked for a thesis case, and ``fit``
prints the spin-down and steady-state results beside tables 7.10 and 7.11.  Nothing else falls
back to these values: the physics takes every vehicle property as an argument.
"""

from __future__ import annotations

# --- the test vehicle (tables 6.3-6.6, section 3) -----------------------------------------------
THESIS_VEHICLE = {
    "mass_kg": 1100.0,
    "effective_mass_kg": 1130.0,
    "frontal_area_m2": 1.85,
    "rolling_radius_m": 0.28,
    "length_m": 4.5,
}
THESIS_COEFFICIENTS = {"AD": 0.01, "BD": 2.0e-4, "CD0": 0.4, "KD": 0.614}
THESIS_FULL_MODEL = {
    "CL0": 0.273,
    "KL": 3.64,
    "KS": 2.4,
    "Cy": 25_000.0,
    "Kalpha": 0.9,
    # alpha = (M l_p / k_p) dv/dt with M = 1100 kg, l_p = 0.55 m (C of G height, reconstructed),
    # k_p = 60e3 N m/rad.
    "pitch_gain": 1100.0 * 0.55 / 60e3,
}
THESIS_DRIVELINE = {"At": 21.0, "Bt": 2.09, "Ct": -0.02}
THESIS_DRIVELINE_ON_LOAD = {"At": 36.3, "Bt": 0.0, "Ct": 0.0}
"""On-load (steady-state) driveline loss, thesis table 7.9: weighted averages of five sets, A_t 36.3 N
(standard error 2.2), B_t 0.0 N s/m (0.11); C_t not fitted (straight line, section 5.5.2)."""
THESIS_UNDRIVEN = {"Au": 3.24, "Bu": 0.232}
THESIS_UNDRIVEN_PER_WHEEL = {
    "nearside": {"Aw": (1.76, 1.58, 1.55), "Bw": (0.117, 0.123, 0.125), "mean": (1.66, 0.121)},
    "offside": {"Aw": (1.57, 1.58, 1.58), "Bw": (0.109, 0.115, 0.121), "mean": (1.58, 0.114)},
}
"""Thesis table 7.10, undriven (rear) wheel spin-downs, three tests per wheel: A (N) and B (N s/m) of
each test and the table's means (as printed: the nearside A tests as transcribed average 1.63, not
1.66; the totals use the printed means).  Vehicle totals ``THESIS_UNDRIVEN``: A_u = 3.24 N (std
0.155, 4.8 %), B_u = 0.232 N s/m (std 0.012, 5.1 %; the printed means add up to 0.235)."""
THESIS_UNDRIVEN_SD = {"Au": 0.155, "Bu": 0.012}
"""Table 7.10's "total std. dev." of A_u and B_u."""
THESIS_WHEEL_INERTIA_KGM2 = 0.59
"""Polar moment of inertia of one wheel of the thesis car *(reconstructed: the transcript gives
none; M_e - M = 30 kg over four wheels at R_r = 0.28 m, drivetrain inertia neglected)*."""
THESIS_TABLE_7_11 = {
    "coastdown_low_wind": {"AD": 0.0094, "BD": 0.231e-3, "CD0": 0.386},
    "coastdown_high_wind": {"AD": 0.0103, "BD": 0.260e-3, "CD0": 0.384},
    "coastdown_set_of_24": {"AD": 0.0098, "BD": 0.233e-3, "CD0": 0.391},
    "steady_state": {"AD": 0.0110, "BD": 0.208e-3, "CD0": 0.410},
    "wind_tunnel": {"CD0": 0.401},
    "std_pct": {"coastdown_low_wind": {"AD": 5.5, "BD": 31.4, "CD0": 8.3},
                "coastdown_high_wind": {"AD": 6.2, "BD": 31.2, "CD0": 9.6},
                "coastdown_set_of_24": {"AD": 4.9, "BD": 27.3, "CD0": 6.4},
                "steady_state": {"AD": 7.6, "BD": 131.7, "CD0": 12.9}},
}
"""Thesis table 7.11, "Summary of initial study results", transcribed from the transcript: mean
coefficients of the coastdowns (low wind, high wind, the set of 24) and of the five steady-state
sets (table 7.6), with their test-to-test standard deviations in %.  The text: steady state gives
AD ~10 % higher, BD ~12 % lower, the aerodynamic term 4.5 % higher and the total drag at 50 mph
4.5 % higher (tyres transmitting torque, section 2.3.1.6); both within 2.5 % of the tunnel C_D0."""
THESIS_TUNNEL_TABLE = {
    "yaw_deg": [-25.0, -20.0, -15.0, -10.0, -5.0, 0.0, 5.0, 10.0, 15.0, 20.0, 25.0],
    "cd": [0.491, 0.468, 0.455, 0.422, 0.412, 0.401, 0.409, 0.426, 0.456, 0.481, 0.486],
    "cs": [-1.121, -0.873, -0.627, -0.415, -0.208, -0.013, 0.186, 0.387, 0.595, 0.841, 1.101],
    "cl": [0.654, 0.629, 0.515, 0.407, 0.317, 0.273, 0.297, 0.383, 0.530, 0.667, 0.662],
}

# --- the simulation study (tables 6.4-6.6; reconstructions marked in the simulator) -----------
THESIS_WIND = {"scale_length_m": 30.0, "turbulence_ratio": 0.4, "bandwidth_hz": 1.0}
"""Dryden scale length of head and cross wind, sigma / mean wind, noise band DC-1 Hz (table 6.4)."""
THESIS_SENSORS = {"cup_distance_constant_m": 1.5, "vane_damping_ratio": 0.4, "vane_damped_wavelength_m": 5.0}
"""Cup anemometer and yaw vane characteristics (table 6.5, section 3 of the reference)."""
THESIS_MEASUREMENT_NOISE = {"speed_mps": 0.05, "airspeed_mps": 0.05, "yaw_rad": 0.01, "driveline_force_n": 1.0}
"""Standard deviations of the measurement noise (table 6.6; driveline: this project's choice)."""
THESIS_SYSTEM_NOISE = {"AD": 1.0e-4, "BD": 1.0e-5, "CD0": 5.0e-3}
"""Standard deviations of the system noise on the coefficients (table 6.6)."""
