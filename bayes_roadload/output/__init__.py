"""Output: the fit directory of every data kind (:mod:`.fitdir`) and the report rendered from it
(:mod:`.report`)."""

from .fitdir import FIT_FILES as FIT_FILES
from .fitdir import FitDir as FitDir
from .fitdir import fit_provenance as fit_provenance
from .fitdir import fit_record as fit_record
from .fitdir import fit_campaign as fit_campaign
from .fitdir import fit_gates as fit_gates
from .fitdir import is_fit_dir as is_fit_dir
from .fitdir import read_fit_dir as read_fit_dir
from .fitdir import write_fit_dir as write_fit_dir
from .fitdir import write_lsq_fit_dir as write_lsq_fit_dir
from .report import render_report as render_report
