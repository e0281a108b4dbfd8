"""The performance evaluator (Tong 2018, section 3.4): trials that plan with OMPL and drive in
PyBullet, one at a time or as a parallel, resumable experiment with tables and figures."""

from ._errors import ExperimentError as ExperimentError
from ._errors import OutputError as OutputError
from ._manifest import read_manifest as read_manifest
from ._outputs import WRITTEN_BY as WRITTEN_BY
from ._outputs import atomic_path as atomic_path
from ._outputs import atomic_write as atomic_write
from ._outputs import check_output_file as check_output_file
from ._outputs import is_partial as is_partial
from ._outputs import marked as marked
from ._outputs import prepare_output_folder as prepare_output_folder
from ._runner import ExperimentReport as ExperimentReport
from ._runner import check_results_folder as check_results_folder
from ._runner import describe_best as describe_best
from ._runner import rerun_trial as rerun_trial
from ._runner import run_experiment as run_experiment
from ._spec import ExperimentSpec as ExperimentSpec
from ._spec import list_experiments as list_experiments
from ._spec import load_experiment as load_experiment
from ._store import ResultStore as ResultStore
from ._summary import RouteSummary as RouteSummary
from ._summary import format_table as format_table
from ._summary import summarize as summarize
from ._trial import LabelledPlan as LabelledPlan
from ._trial import TrialResult as TrialResult
from ._trial import drive as drive
from ._trial import finish_trial as finish_trial
from ._trial import plan as plan
from ._trial import plan_many as plan_many
from ._trial import reference_energy as reference_energy
from ._trial import run_trial as run_trial
