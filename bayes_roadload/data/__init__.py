"""The campaign data contract (``docs/data-format.md``): load, validate, save."""

from .campaign import Anemometer as Anemometer
from .campaign import Campaign as Campaign
from .campaign import CampaignError as CampaignError
from .campaign import Vehicle as Vehicle
from .campaign import load_campaign as load_campaign
from .campaign import save_campaign as save_campaign
from .distances import DistanceCampaign as DistanceCampaign
from .intervals import IntervalCampaign as IntervalCampaign
from .spindown import SpindownCampaign as SpindownCampaign
from .spindown import load_spindown as load_spindown
from .spindown import save_spindown as save_spindown
from .steady import SteadyCampaign as SteadyCampaign
from .steady import load_steady as load_steady
from .steady import save_steady as save_steady
