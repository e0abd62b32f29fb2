"""Pure-JAX physics: drag terms, drag models, air density and the RK4 integrator.

Nothing in this layer imports numpyro or ArviZ.
"""

from .atmosphere import REFERENCE_AIR_DENSITY_KGPM3 as REFERENCE_AIR_DENSITY_KGPM3
from .atmosphere import air_density_kgpm3 as air_density_kgpm3
from .integrate import RunBatch as RunBatch
from .integrate import make_run as make_run
from .integrate import stack_runs as stack_runs
from .integrate import integrate_batch as integrate_batch
from .integrate import integrate_batch_forward_sensitivity as integrate_batch_forward_sensitivity
from .integrate import integrate_run as integrate_run
from .integrate import quadratic_coastdown_speed as quadratic_coastdown_speed
from .integrate import quadratic_coastdown_time as quadratic_coastdown_time
from .model import DragModel as DragModel
from .model import MeasuredAir as MeasuredAir
from .model import StillAir as StillAir
from .model import WindAir as WindAir
from .model import full_model as full_model
from .model import model_from_names as model_from_names
from .model import simplified_model as simplified_model
from .terms import TERMS as TERMS
from . import effects as effects  # registers the candidate-effect terms
from .effects import OffsetAir as OffsetAir
from .terms import Conditions as Conditions
from .terms import Term as Term
from .terms import register_term as register_term
from .spindown import spindown_interval_drag_n as spindown_interval_drag_n
from .spindown import spindown_speed_mps as spindown_speed_mps
