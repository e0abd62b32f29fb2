"""Coastdown simulator (thesis chapter 6): Dryden wind frozen along the track, anemometer and
vehicle dynamics, measurement and system noise, and the 19 cases of table 6.7, producing
campaigns in the data contract format (:class:`bayes_roadload.data.Campaign`)."""

from .campaign import DEFAULT_SETTINGS as DEFAULT_SETTINGS
from .campaign import SimulationSettings as SimulationSettings
from .campaign import case_model as case_model
from .campaign import simulate_campaign as simulate_campaign
from .campaign import simulate_true_runs as simulate_true_runs
from .campaign import true_parameters as true_parameters
from .cases import CASES as CASES
from .cases import SimulationCase as SimulationCase
from .cases import get_case as get_case
from .sensors import DEFAULT_SENSORS as DEFAULT_SENSORS
from .sensors import SensorConfig as SensorConfig
from .sensors import simulate_sensor_step as simulate_sensor_step
from .wind import WindField as WindField
from .wind import dryden_psd as dryden_psd
from .wind import dryden_psd_lateral as dryden_psd_lateral
from .wind import dryden_psd_longitudinal as dryden_psd_longitudinal
from .wind import generate_wind_field as generate_wind_field
from .wind import mean_wind_profile as mean_wind_profile
from .wind import synthesize_turbulence as synthesize_turbulence
from .spindown import simulate_spindown as simulate_spindown
from .steady import simulate_steady as simulate_steady
