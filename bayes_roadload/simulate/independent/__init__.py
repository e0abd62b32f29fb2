"""An independent coastdown simulator: its own vehicles, wind field, track, instruments and
integrator (scipy ``solve_ivp``), sharing no physics code or constants with the analysis.  It
shares only the campaign contract (``docs/data-format.md``) and the definition of the true
parameters (:mod:`.reference`); see ``docs/independent_simulator.md``."""

from .campaign import CHANNELS as CHANNELS
from .campaign import DEFAULT_CHANNELS as DEFAULT_CHANNELS
from .campaign import apply_effects as apply_effects
from .campaign import first_draws as first_draws
from .campaign import simulate_independent as simulate_independent
from .campaign import true_roadload as true_roadload
from .dynamics import AnemometerDynamics as AnemometerDynamics
from .dynamics import RunConditions as RunConditions
from .dynamics import RunTrace as RunTrace
from .dynamics import simulate_run as simulate_run
from .effects import EFFECTS as EFFECTS
from .effects import TYPE_B as TYPE_B
from .effects import Effect as Effect
from .sensors import Instruments as Instruments
from .track import Track as Track
from .vehicles import CATEGORIES as CATEGORIES
from .vehicles import TrueVehicle as TrueVehicle
from .vehicles import random_vehicle as random_vehicle
from .wind import WindField as WindField
