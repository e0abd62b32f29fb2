"""The names of the campaign contract under one module: the speed-trace :class:`Campaign`,
the vehicle file, the shared checks and the loading and saving of every kind.

Definitions live in :mod:`.checks` (shared checks, :class:`CampaignError`, file helpers),
:mod:`.vehicle` (``vehicle.toml``), :mod:`.traces` (the speed-trace kind) and :mod:`.io`
(:func:`load_campaign` / :func:`save_campaign` of every kind); this module re-exports them.
"""

from .checks import CHANNEL_LIMITS as CHANNEL_LIMITS
from .checks import UNIT_HINTS as UNIT_HINTS
from .checks import CampaignError as CampaignError
from .checks import check_columns as check_columns
from .checks import check_contiguous as check_contiguous
from .checks import check_direction_codes as check_direction_codes
from .checks import check_numeric as check_numeric
from .checks import check_run_constants as check_run_constants
from .checks import check_time_increases as check_time_increases
from .checks import consecutive_pairs as consecutive_pairs
from .checks import pairs_by_column as pairs_by_column
from .checks import refuse as refuse
from .checks import run_directions as run_directions
from .checks import run_ids_of as run_ids_of
from .checks import subset_table as subset_table
from .checks import write_atomically as write_atomically
from .io import load_campaign as load_campaign
from .io import save_campaign as save_campaign
from .traces import KNOWN_COLUMNS as KNOWN_COLUMNS
from .traces import OPTIONAL_COLUMNS as OPTIONAL_COLUMNS
from .traces import REQUIRED_COLUMNS as REQUIRED_COLUMNS
from .traces import Campaign as Campaign
from .traces import validate_runs as validate_runs
from .vehicle import Anemometer as Anemometer
from .vehicle import Vehicle as Vehicle
from .vehicle import read_vehicle_file as read_vehicle_file
from .vehicle import validate_vehicle as validate_vehicle
from .vehicle import vehicle_toml as vehicle_toml
