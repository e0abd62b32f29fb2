"""The campaign data contract (``docs/data-format.md``): load, validate, save.

One module per kind of campaign data (:mod:`.traces`, :mod:`.intervals`, :mod:`.distances`,
:mod:`.spindown`, :mod:`.steady`), each following :class:`~.io.CampaignKind`; :mod:`.io` loads
and saves any of them through :data:`~.io.DATA_KINDS`.  :mod:`.checks` holds the checks they
share, :mod:`.vehicle` the ``vehicle.toml`` format.
"""

from .checks import CampaignError as CampaignError
from .checks import write_atomically as write_atomically
from .distances import DistanceCampaign as DistanceCampaign
from .intervals import IntervalCampaign as IntervalCampaign
from .io import DATA_KINDS as DATA_KINDS
from .io import campaign_sha256 as campaign_sha256
from .io import CampaignKind as CampaignKind
from .io import data_kind as data_kind
from .io import find_kind as find_kind
from .io import kind_of as kind_of
from .io import load_campaign as load_campaign
from .io import save_campaign as save_campaign
from .spindown import SpindownCampaign as SpindownCampaign
from .spindown import load_spindown as load_spindown
from .spindown import save_spindown as save_spindown
from .steady import SteadyCampaign as SteadyCampaign
from .steady import load_steady as load_steady
from .steady import save_steady as save_steady
from .traces import Campaign as Campaign
from .vehicle import Anemometer as Anemometer
from .vehicle import Vehicle as Vehicle
from .vehicle import read_vehicle_file as read_vehicle_file
