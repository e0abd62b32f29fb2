"""Analyses built on the physics and inference layers: coefficient sensitivity (thesis
section 6.3), the batch door for studies of many fits (:mod:`.batch`), the validation
studies, test planning (:mod:`.planning`, :mod:`.regulation`) and the sim-to-real diagnosis
(:mod:`.gap`, :mod:`.effects`, :mod:`.diagnose`, :mod:`.replay`)."""

from .sensitivity import PUBLISHED_KD_SENSITIVITY_MPS as PUBLISHED_KD_SENSITIVITY_MPS
from .sensitivity import PUBLISHED_SENSITIVITY_MPS as PUBLISHED_SENSITIVITY_MPS
from .sensitivity import SensitivitySettings as SensitivitySettings
from .sensitivity import coefficient_sensitivity as coefficient_sensitivity
from .sensitivity import compare_with_thesis as compare_with_thesis
from .sensitivity import format_sensitivity_table as format_sensitivity_table
