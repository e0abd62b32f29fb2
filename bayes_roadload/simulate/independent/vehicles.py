"""Random vehicles from a small car to a heavy truck, with their true properties.

Each category gives uniform ranges; every range carries its source.  The aerodynamic drag has
the analysis' form ``CD0 + KD psi^2`` (so the truth is defined) plus an optional quartic
``K4 psi^4`` (the flattening of C_D at large yaw seen in tunnel tables); the rolling resistance
has this simulator's own law (load x (c0 + c1 v + c2 v^2), SAE J2452 form, times a tyre
temperature factor of its own).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

# Each entry: (low, high).  Sources in the comments.
CATEGORIES: dict[str, dict[str, tuple[float, float]]] = {
    "small_car": {
        "mass_kg": (900.0, 1250.0),            # thesis Escort 1125 kg; EU A/B segment kerb + driver
        "frontal_area_m2": (1.8, 2.1),         # thesis 1.83-1.85 m^2
        "cd0": (0.30, 0.40),                   # thesis tunnel 0.385-0.401; modern B segment 0.30-0.34
        "kd_per_rad2": (0.4, 1.2),             # thesis tunnel 0.458-0.614, track 0.98-1.72
        "rr_c0": (0.007, 0.011),               # thesis A_D 0.0094-0.0100; EU tyre label classes B-E
        "rr_c1_s_per_m": (0.5e-4, 2.5e-4),     # thesis B_D 0.214e-3 s/m
        "rotating_fraction": (0.02, 0.04),     # J2263: 1.03 M when the inertia is unknown
        "rolling_radius_m": (0.27, 0.31),      # 13-15 inch wheels
        "length_m": (3.6, 4.1),                # thesis 3.97 m
        "cl0": (0.15, 0.35),                   # thesis C_L0 0.273
        "kl_per_rad2": (1.5, 4.0),             # thesis K_L 1.78-3.64
        "ks_per_rad": (1.8, 3.0),              # thesis K_S 2.4
        "tyre_cornering_n_per_rad": (20e3, 45e3),  # thesis C_y 25000 N/rad per tyre
        "cg_height_m": (0.45, 0.58),           # thesis l_p = C of G height (~0.5 m)
        "pitch_stiffness_nm_per_rad": (40e3, 90e3),  # thesis k_p 60e3 N m/rad
        "k_alpha_per_rad": (0.5, 1.3),         # thesis K_alpha 0.9
        "driveline_a_n": (10.0, 35.0),         # thesis table 8.12 A_t 21.0 / 25.5 N
        "driveline_b_nspm": (0.8, 2.5),        # thesis B_t 1.41-2.09 N s/m
        "driveline_c_ns2pm2": (-0.03, 0.02),   # thesis C_t -0.02
    },
    "mid_car": {
        "mass_kg": (1300.0, 1750.0),           # EU C/D segment test masses (GTR 15 TM_low..TM_high)
        "frontal_area_m2": (2.1, 2.4),
        "cd0": (0.25, 0.33),                   # published C_D of current saloons/estates
        "kd_per_rad2": (0.4, 1.2),
        "rr_c0": (0.006, 0.010),
        "rr_c1_s_per_m": (0.5e-4, 2.0e-4),
        "rotating_fraction": (0.02, 0.04),
        "rolling_radius_m": (0.30, 0.34),
        "length_m": (4.3, 4.9),
        "cl0": (0.05, 0.25),
        "kl_per_rad2": (1.0, 3.5),
        "ks_per_rad": (1.8, 3.0),
        "tyre_cornering_n_per_rad": (35e3, 70e3),
        "cg_height_m": (0.48, 0.60),
        "pitch_stiffness_nm_per_rad": (60e3, 140e3),
        "k_alpha_per_rad": (0.5, 1.3),
        "driveline_a_n": (15.0, 45.0),
        "driveline_b_nspm": (1.0, 3.0),
        "driveline_c_ns2pm2": (-0.03, 0.03),
    },
    "suv_van": {
        "mass_kg": (1800.0, 2800.0),           # large SUVs and N1 vans
        "frontal_area_m2": (2.6, 3.6),
        "cd0": (0.32, 0.42),
        "kd_per_rad2": (0.8, 2.5),
        "rr_c0": (0.007, 0.011),
        "rr_c1_s_per_m": (0.5e-4, 2.0e-4),
        "rotating_fraction": (0.02, 0.045),
        "rolling_radius_m": (0.33, 0.38),
        "length_m": (4.6, 5.4),
        "cl0": (0.05, 0.25),
        "kl_per_rad2": (1.0, 3.0),
        "ks_per_rad": (2.0, 3.5),
        "tyre_cornering_n_per_rad": (50e3, 90e3),
        "cg_height_m": (0.60, 0.80),
        "pitch_stiffness_nm_per_rad": (100e3, 250e3),
        "k_alpha_per_rad": (0.5, 1.3),
        "driveline_a_n": (20.0, 60.0),
        "driveline_b_nspm": (1.5, 4.0),
        "driveline_c_ns2pm2": (-0.04, 0.04),
    },
    "light_truck": {
        "mass_kg": (3500.0, 7500.0),           # N2 rigid trucks
        "frontal_area_m2": (4.5, 6.5),
        "cd0": (0.45, 0.65),                   # box-body rigid trucks
        "kd_per_rad2": (2.0, 6.0),             # C_D rises 20-40 % at 10 deg yaw (wind-averaged drag, SAE J1252)
        "rr_c0": (0.005, 0.008),               # truck tyre label classes
        "rr_c1_s_per_m": (0.3e-4, 1.0e-4),
        "rotating_fraction": (0.02, 0.05),
        "rolling_radius_m": (0.36, 0.42),
        "length_m": (6.0, 8.5),
        "cl0": (0.0, 0.15),
        "kl_per_rad2": (0.0, 1.5),
        "ks_per_rad": (3.0, 5.0),
        "tyre_cornering_n_per_rad": (60e3, 120e3),
        "cg_height_m": (0.9, 1.3),
        "pitch_stiffness_nm_per_rad": (400e3, 900e3),
        "k_alpha_per_rad": (0.3, 1.0),
        "driveline_a_n": (40.0, 120.0),
        "driveline_b_nspm": (3.0, 8.0),
        "driveline_c_ns2pm2": (-0.05, 0.08),
    },
    "heavy_truck": {
        "mass_kg": (15000.0, 40000.0),         # 40 CFR 1066.310 (above 14,000 lb): tractor-trailers
        "frontal_area_m2": (8.5, 10.5),
        "cd0": (0.50, 0.70),                   # tractor-trailer C_D (40 CFR 1037.528 CdA bins)
        "kd_per_rad2": (3.0, 8.0),             # wind-averaged vs zero-yaw drag (40 CFR 1037.528)
        "rr_c0": (0.004, 0.007),               # EU truck tyre label 4-7 kg/t
        "rr_c1_s_per_m": (0.2e-4, 0.8e-4),
        "rotating_fraction": (0.02, 0.05),
        "rolling_radius_m": (0.48, 0.53),
        "length_m": (15.0, 16.5),
        "cl0": (0.0, 0.10),
        "kl_per_rad2": (0.0, 1.0),
        "ks_per_rad": (4.0, 7.0),
        "tyre_cornering_n_per_rad": (150e3, 250e3),
        "cg_height_m": (1.2, 1.8),
        "pitch_stiffness_nm_per_rad": (3e6, 8e6),
        "k_alpha_per_rad": (0.2, 0.8),
        "driveline_a_n": (100.0, 300.0),
        "driveline_b_nspm": (5.0, 15.0),
        "driveline_c_ns2pm2": (-0.1, 0.2),
    },
}

TYRES_OF = {"small_car": 4, "mid_car": 4, "suv_van": 4, "light_truck": 6, "heavy_truck": 18}

COMMON_RANGES: dict[str, tuple[float, float]] = {
    # quadratic part of the rolling resistance coefficient: +5..+20 % from 15 to 115 km/h
    # beyond the linear term (SAE J2452 A + B v + C v^2 form)
    "rr_c2_rise": (0.05, 0.20),
    # C_D flattening at large yaw: the +-15 and +-25 deg tunnel fits of the thesis differ
    # (K_D 0.614 vs 0.458 rad^-2), a negative quartic of this size
    "k4_over_kd_per_rad2": (-3.0, -0.5),
    # tyre rolling resistance temperature coefficient, 0.6-1.2 %/K (GTR 15 uses 0.86 %/K)
    "tyre_temp_coeff_per_k": (0.006, 0.012),
    # tyre carcass thermal time constant (SAE J2452 / GTR 15 warm-up of 20-30 min: several minutes)
    "tyre_tau_s": (200.0, 900.0),
    # steady tyre temperature rise above ambient per m/s (tyres 15-25 K above ambient at 30 m/s)
    "tyre_rise_k_per_mps": (0.4, 0.8),
    # change in C_D per metre of ride-height rise (about 0.001-0.003 per 10 mm, literature)
    "ride_height_cd_per_m": (0.1, 0.3),
    # share of the aerodynamic side force carried by the front axle
    "front_side_share": (0.4, 0.7),
    # suspension heave stiffness per unit test mass, N/m per kg (body frequency 1.1-1.6 Hz)
    "heave_stiffness_per_kg": (48.0, 100.0),
}


@dataclass(frozen=True)
class TrueVehicle:
    """The true vehicle (SI).  Tyre law: ``F = load (rr_c0 + rr_c1 v + rr_c2 v^2)``, load the
    wheel load in N, times the tyre temperature factor of :mod:`.dynamics`."""

    category: str
    mass_kg: float
    rotating_inertia_kgm2: float
    rolling_radius_m: float
    frontal_area_m2: float
    length_m: float
    cd0: float
    kd_per_rad2: float
    k4_per_rad4: float
    cl0: float
    kl_per_rad2: float
    ks_per_rad: float
    axle_cornering_front_n_per_rad: float
    axle_cornering_rear_n_per_rad: float
    front_side_share: float
    k_alpha_per_rad: float
    cg_height_m: float
    pitch_stiffness_nm_per_rad: float
    ride_height_cd_per_m: float
    heave_stiffness_n_per_m: float
    rr_c0: float
    rr_c1_s_per_m: float
    rr_c2_s2_per_m2: float
    tyre_temp_coeff_per_k: float
    tyre_temperature_law: str          # "linear" (the GTR 15 form) or "exponential"
    tyre_tau_s: float
    tyre_rise_k_per_mps: float
    driveline_a_n: float
    driveline_b_nspm: float
    driveline_c_ns2pm2: float

    @property
    def effective_mass_kg(self) -> float:
        """M + I / R^2 (wheels and the driveline turning with them)."""
        return self.mass_kg + self.rotating_inertia_kgm2 / self.rolling_radius_m**2

    @property
    def has_driveline(self) -> bool:
        return any(x != 0.0 for x in (self.driveline_a_n, self.driveline_b_nspm, self.driveline_c_ns2pm2))

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def random_vehicle(rng: np.random.Generator, category: str | None = None) -> TrueVehicle:
    """Draw a vehicle: the category uniformly from :data:`CATEGORIES` unless given, then
    every property uniformly in its range."""
    if category is None:
        category = str(rng.choice(sorted(CATEGORIES)))
    if category not in CATEGORIES:
        raise ValueError(f"unknown vehicle category {category!r}; one of {sorted(CATEGORIES)}")
    r = {k: float(rng.uniform(*lim)) for k, lim in CATEGORIES[category].items()}
    c = {k: float(rng.uniform(*lim)) for k, lim in COMMON_RANGES.items()}
    radius = r["rolling_radius_m"]
    inertia = r["rotating_fraction"] * r["mass_kg"] * radius**2
    # quadratic rolling-resistance part: rr_c2 v^2 adds rr_c2_rise x c0 at 115 km/h
    v_top = 115.0 / 3.6
    rr_c2 = c["rr_c2_rise"] * r["rr_c0"] / v_top**2
    n_tyres = TYRES_OF[category]
    axle = r["tyre_cornering_n_per_rad"] * n_tyres / 2.0
    return TrueVehicle(
        category=category, mass_kg=r["mass_kg"], rotating_inertia_kgm2=inertia, rolling_radius_m=radius,
        frontal_area_m2=r["frontal_area_m2"], length_m=r["length_m"], cd0=r["cd0"],
        kd_per_rad2=r["kd_per_rad2"], k4_per_rad4=c["k4_over_kd_per_rad2"] * r["kd_per_rad2"],
        cl0=r["cl0"], kl_per_rad2=r["kl_per_rad2"], ks_per_rad=r["ks_per_rad"],
        axle_cornering_front_n_per_rad=axle, axle_cornering_rear_n_per_rad=axle,
        front_side_share=c["front_side_share"], k_alpha_per_rad=r["k_alpha_per_rad"],
        cg_height_m=r["cg_height_m"], pitch_stiffness_nm_per_rad=r["pitch_stiffness_nm_per_rad"],
        ride_height_cd_per_m=c["ride_height_cd_per_m"],
        heave_stiffness_n_per_m=c["heave_stiffness_per_kg"] * r["mass_kg"],
        rr_c0=r["rr_c0"], rr_c1_s_per_m=r["rr_c1_s_per_m"], rr_c2_s2_per_m2=rr_c2,
        tyre_temp_coeff_per_k=c["tyre_temp_coeff_per_k"], tyre_temperature_law="exponential",
        tyre_tau_s=c["tyre_tau_s"], tyre_rise_k_per_mps=c["tyre_rise_k_per_mps"],
        driveline_a_n=r["driveline_a_n"], driveline_b_nspm=r["driveline_b_nspm"],
        driveline_c_ns2pm2=r["driveline_c_ns2pm2"],
    )
