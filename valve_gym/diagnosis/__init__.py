"""Model-mismatch diagnosis of control-loop recordings.

Fit the valve/process simulator to a recording by free-run simulation error,
locate where and under which operating conditions it misses, name the missing
physics by refitting with candidate effects (information criterion + held-out
error), and judge whether the valve sticks.

Public API
----------
load_recording, Recording, RecordingError, data_path
    read and validate a recording (CSV).
ModelFitter
    scikit-learn style estimator: ``ModelFitter(plant, actuator, effects).fit(rec)``.
diagnose, diagnose_many, DiagnosisResult
    the whole chain for one recording / many in parallel.
locate_mismatch, MismatchReport
    residual analysis in time and by operating condition.
SelectionRule
    when an extra model element pays.
horch_ccf
    Horch's model-free cross-correlation stiction test (a second opinion).
write_report, write_json
    figures, JSON and markdown (matplotlib imported lazily).

Examples
--------
>>> from valve_gym.diagnosis import diagnose
>>> from valve_gym.diagnosis.synthetic import make_recording
>>> res = diagnose(make_recording("none", seed=4, n=300), candidates=(), effort="fast")
>>> res.effects
[]
"""
from .causes import OscillationCause, oscillation_cause
from .diagnose import DiagnosisResult, diagnose, diagnose_many, validate_on
from .fit import FitResult, ModelFitter, fit_percent, rmse
from .indices import horch_ccf
from .locate import MismatchReport, locate_mismatch
from .model import ACTUATORS, CANDIDATE_EFFECTS, PLANTS
from .recording import Recording, RecordingError, data_path, load_recording
from .report import write_json, write_report
from .select import SelectionRule

__all__ = ["load_recording", "Recording", "RecordingError", "data_path", "ModelFitter",
           "FitResult", "diagnose", "diagnose_many", "DiagnosisResult", "validate_on",
           "locate_mismatch", "MismatchReport", "SelectionRule", "write_report", "write_json",
           "rmse", "fit_percent", "PLANTS", "ACTUATORS", "CANDIDATE_EFFECTS", "horch_ccf", "OscillationCause",
           "oscillation_cause"]
