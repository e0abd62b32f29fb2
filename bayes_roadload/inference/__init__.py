"""Inference: model variants as data (:mod:`.spec`) and the classical least-squares baseline
(:mod:`.lsq`).  The Bayesian models and samplers build on the same :class:`ModelSpec`; every
data kind's fit problem implements :class:`Problem` (:mod:`.problem`), and :mod:`.kinds` is the
registry of data kinds."""

from .lsq import DEFAULT_LSQ as DEFAULT_LSQ
from .lsq import GroupFit as GroupFit
from .lsq import LsqResult as LsqResult
from .lsq import LsqSettings as LsqSettings
from .lsq import fit_lsq as fit_lsq
from .lsq import format_lsq_table as format_lsq_table
from .lsq import roadload_figures as roadload_figures
from .lsq import weighted_mean as weighted_mean
from .lsq import lsq_record as lsq_record
from .problem import Problem as Problem
from .spec import ModelSpec as ModelSpec
from .spec import ModelSpecError as ModelSpecError
from .spec import Prior as Prior
from .spec import available_models as available_models
from .spec import load_model_spec as load_model_spec
