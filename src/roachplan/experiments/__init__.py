"""The performance evaluator (Tong 2018, section 3.4): trials that plan with OMPL and drive in
PyBullet, one at a time or as a parallel, resumable experiment with tables and figures."""

from typing import TYPE_CHECKING

from roachplan._lazy import lazy_exports

# Public names, imported on first use (roachplan._lazy): the command line answers at once.
_getattr, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "BenchmarkResult": "._benchmark",
        "benchmark_bar": "._benchmark",
        "benchmark_log": "._benchmark",
        "is_benchmark_db": "._benchmark",
        "run_benchmark": "._benchmark",
        "write_benchmark_db": "._benchmark",
        "CandidatePlan": "._choose_candidate",
        "Knockout": "._choose_candidate",
        "OutReason": "._choose_candidate",
        "Standing": "._choose_candidate",
        "ChooseConfig": "._choose_config",
        "DEFAULT_MODE": "._choose_config",
        "QUICK_MODE": "._choose_config",
        "Guarantee": "._choose_certify",
        "CandidatesPlanned": "._choose_events",
        "ChooseEvent": "._choose_events",
        "Decided": "._choose_events",
        "CrossChecked": "._choose_events",
        "tally_lines": "._cross_check",
        "KnockedOut": "._choose_events",
        "RoundDone": "._choose_events",
        "StopReason": "._choose_events",
        "Choice": "._choose_race",
        "choose": "._choose",
        "ChooseError": "._errors",
        "ExperimentError": "._errors",
        "OutputError": "._errors",
        "MANIFEST": "._manifest",
        "check_same_world": "._manifest",
        "read_manifest": "._manifest",
        "spec_from_manifest": "._manifest",
        "WRITTEN_BY": "._outputs",
        "atomic_path": "._outputs",
        "atomic_write": "._outputs",
        "check_output_file": "._outputs",
        "is_partial": "._outputs",
        "marked": "._outputs",
        "prepare_output_folder": "._outputs",
        "ExperimentReport": "._runner",
        "check_results_folder": "._runner",
        "describe_best": "._runner",
        "rerun_trial": "._runner",
        "run_experiment": "._runner",
        "ExperimentSpec": "._spec",
        "list_experiments": "._library",
        "load_experiment": "._spec",
        "reference_settings": "._spec",
        "ResultStore": "._store",
        "RouteSummary": "._summary",
        "format_markdown": "._summary",
        "format_table": "._summary",
        "summarize": "._summary",
        "LabelledPlan": "._trial",
        "TrialResult": "._trial",
        "drive": "._trial",
        "finish_trial": "._trial",
        "plan": "._trial",
        "path_settings": "._trial",
        "plan_many": "._trial",
        "reference_energy": "._trial",
        "run_trial": "._trial",
        "LocalPool": "._workers",
        "WorldDraw": "._uncertainty",
        "draw": "._uncertainty",
    },
)
if not TYPE_CHECKING:  # (a type checker sees the names imported below instead, and so
    # reports an import from here of a name that is not one of them)
    __getattr__ = _getattr
del _getattr

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and editors
    from ._benchmark import BenchmarkResult as BenchmarkResult
    from ._benchmark import benchmark_bar as benchmark_bar
    from ._benchmark import benchmark_log as benchmark_log
    from ._benchmark import is_benchmark_db as is_benchmark_db
    from ._benchmark import run_benchmark as run_benchmark
    from ._benchmark import write_benchmark_db as write_benchmark_db
    from ._choose import choose as choose
    from ._choose_candidate import CandidatePlan as CandidatePlan
    from ._choose_candidate import Knockout as Knockout
    from ._choose_candidate import OutReason as OutReason
    from ._choose_candidate import Standing as Standing
    from ._choose_certify import Guarantee as Guarantee
    from ._choose_config import DEFAULT_MODE as DEFAULT_MODE
    from ._choose_config import QUICK_MODE as QUICK_MODE
    from ._choose_config import ChooseConfig as ChooseConfig
    from ._choose_events import CandidatesPlanned as CandidatesPlanned
    from ._choose_events import ChooseEvent as ChooseEvent
    from ._choose_events import CrossChecked as CrossChecked
    from ._choose_events import Decided as Decided
    from ._choose_events import KnockedOut as KnockedOut
    from ._choose_events import RoundDone as RoundDone
    from ._choose_events import StopReason as StopReason
    from ._choose_race import Choice as Choice
    from ._cross_check import tally_lines as tally_lines
    from ._errors import ChooseError as ChooseError
    from ._errors import ExperimentError as ExperimentError
    from ._errors import OutputError as OutputError
    from ._library import list_experiments as list_experiments
    from ._manifest import MANIFEST as MANIFEST
    from ._manifest import check_same_world as check_same_world
    from ._manifest import read_manifest as read_manifest
    from ._manifest import spec_from_manifest as spec_from_manifest
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
    from ._spec import load_experiment as load_experiment
    from ._spec import reference_settings as reference_settings
    from ._store import ResultStore as ResultStore
    from ._summary import RouteSummary as RouteSummary
    from ._summary import format_markdown as format_markdown
    from ._summary import format_table as format_table
    from ._summary import summarize as summarize
    from ._trial import LabelledPlan as LabelledPlan
    from ._trial import TrialResult as TrialResult
    from ._trial import drive as drive
    from ._trial import finish_trial as finish_trial
    from ._trial import path_settings as path_settings
    from ._trial import plan as plan
    from ._trial import plan_many as plan_many
    from ._trial import reference_energy as reference_energy
    from ._trial import run_trial as run_trial
    from ._uncertainty import WorldDraw as WorldDraw
    from ._uncertainty import draw as draw
    from ._workers import LocalPool as LocalPool
