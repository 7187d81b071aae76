"""The diagnosis results are typed and frozen: built once, rendered in words by the explain module."""
from __future__ import annotations

import ast
import dataclasses
import math
from pathlib import Path

import pytest

from valve_gym.diagnosis import DiagnosisResult, diagnose
from valve_gym.diagnosis.explain import explain_friction
from valve_gym.diagnosis.synthetic import make_recording
from valve_gym.diagnosis.verdict import FreeRunTest, FrictionVerdict, KStepTest

PKG = Path(__file__).resolve().parents[1] / "valve_gym" / "diagnosis"
#: The modules that run a diagnosis and decide and write its friction verdict.
STAGE_MODULES = ("diagnose.py", "verdict.py", "explain.py", "causes.py", "stiction/assess.py", "stiction/combine.py")
#: Most positional parameters a function of those modules takes (options are keyword-only).
MAX_POSITIONAL = 6
#: The batch engine keeps its public signature (``jobs`` positional) for its callers.
PUBLIC_EXCEPTIONS = {"diagnose_many"}


@pytest.fixture(scope="module")
def result():
    return diagnose(make_recording("none", seed=4, n=300), candidates=(), effort="fast")


def test_result_and_verdict_are_frozen(result):
    assert isinstance(result, DiagnosisResult) and isinstance(result.stiction, FrictionVerdict)
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.stiction = FrictionVerdict.untested()        # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.validation = {}                              # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.stiction.present = True                      # type: ignore[misc]
    with pytest.raises(TypeError):                          # the JSON view reads, it does not write
        result.stiction["present"] = True                   # type: ignore[index]
    for part in (result.stiction.free_run, result.stiction.kstep, result.stiction.combined):
        if part is not None:
            assert dataclasses.is_dataclass(part) and type(part).__dataclass_params__.frozen  # type: ignore[union-attr]


def _strings(obj, path="verdict"):
    """Every string a verdict holds in its own fields (the methods' evidence and the cause are their own records)."""
    if isinstance(obj, str):
        yield path, obj
    elif isinstance(obj, (FrictionVerdict, FreeRunTest, KStepTest)):
        for f in dataclasses.fields(obj):
            if f.name not in ("combined", "overruled_by", "horch", "reversal", "rule"):
                yield from _strings(getattr(obj, f.name), f"{path}.{f.name}")
    elif isinstance(obj, dict):
        for k, v in obj.items():
            yield from _strings(v, f"{path}[{k!r}]")
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            yield from _strings(v, f"{path}[{i}]")


def test_verdict_holds_no_sentences_and_the_renderer_writes_them(result):
    v = result.stiction
    assert v.tested and v.free_run is not None
    assert "explanation" not in {f.name for f in dataclasses.fields(FrictionVerdict)}
    found = list(_strings(v))
    assert found                                            # it does hold codes and model labels
    for where, s in found:
        # codes ('stem+model', 'slip_jump') and model labels, never a sentence
        assert len(s) <= 60 and not s.rstrip().endswith(".") and s.count(" ") <= 6, (where, s)
    # the paragraph in the JSON is the renderer's, and it is the one the report prints
    d = result.to_dict()["stiction"]
    assert d["explanation"] == explain_friction(v) and len(d["explanation"].split()) > 20
    assert f"- {d['explanation']}" in result_markdown(result)


def result_markdown(result):
    from valve_gym.diagnosis.report import render_markdown
    return render_markdown(result)


def test_verdict_reads_like_its_json(result):
    """The typed verdict and its JSON keys agree (the mapping view is the JSON's values, nan kept)."""
    v = result.stiction
    d = v.to_dict()
    assert set(v) == set(d) and v["present"] is v.present and d["verdict"] == v.verdict
    assert d["probability"] == pytest.approx(v.probability) and d["model_based_present"] is v.model_based_present
    assert d["delta_ic"] == pytest.approx(v.free_run.delta_ic)     # type: ignore[union-attr]
    assert [e["method"] for e in d["evidence"]] == [e.method for e in v.combined.evidence]  # type: ignore[union-attr]
    assert FrictionVerdict.untested().to_dict() == {
        "present": False, "tested": False, "reason": "the actuator is a pump: there is no valve to stick",
        "model": None, "parameters": {}, "naming_agrees": None}
    assert math.isnan(FrictionVerdict.untested().probability) and FrictionVerdict.untested().verdict is None


def _positional(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> list[str]:
    a = fn.args
    return [x.arg for x in a.posonlyargs + a.args if x.arg not in ("self", "cls")]


def test_stage_functions_take_few_positional_parameters():
    """No function of the diagnosis stages takes more than MAX_POSITIONAL positional parameters."""
    offenders = []
    for name in STAGE_MODULES:
        tree = ast.parse((PKG / name).read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name not in PUBLIC_EXCEPTIONS:
                if len(_positional(node)) > MAX_POSITIONAL:
                    offenders.append(f"{name}:{node.lineno} {node.name}({', '.join(_positional(node))})")
    assert not offenders, "bundle the inputs into a typed value, options keyword-only:\n" + "\n".join(offenders)



def test_a_cause_of_the_oscillation_overrules_the_verdict_once():
    """Where another cause explains the oscillation better, the verdict is decided no stiction, not edited."""
    from valve_gym.diagnosis.causes import OscillationCause
    from valve_gym.diagnosis.stiction import StictionAssessment
    from valve_gym.diagnosis.verdict import decide_friction

    nan = float("nan")
    a = StictionAssessment(0.7, "stiction", nan, nan, (nan, nan), (nan, nan), None)
    t = FreeRunTest(parameters={"model": "slip_jump", "S": 0.0, "J": 0.0, "band": 0.0}, delta_ic=3.0,
                    significant=False, band=0.0, slips=0, band_needed=0.01, op_working_range=0.2, n_eff=100.0,
                    frictionless_model="tank + valve", frictionless_rmse=1.0, friction_rmse=1.0, compared={})
    tuning = OscillationCause(True, 120.0, {"stiction": 0.3, "tuning": 0.6, "disturbance": 0.1}, "tuning", ())
    v = decide_friction(t, None, a, tuning)
    d = v.to_dict()
    assert v.present is False and v.overruled_by is tuning and v.present_before_cause is True
    assert (d["verdict"], d["verdict_before_cause"], d["present_before_cause"]) == ("no stiction", "stiction", True)
    assert d["explanation"].endswith("The oscillation is better explained as aggressive tuning (p = 0.60, "
                                     "stiction 0.30): the verdict is no stiction.")
    # a cause that is stiction, or a stiction probability of one half or more, leaves the verdict alone
    for c in (OscillationCause(True, 120.0, {"stiction": 0.6, "tuning": 0.4}, "stiction", ()),
              OscillationCause(True, 120.0, {"stiction": 0.5, "tuning": 0.5}, "tuning", ()), None):
        v = decide_friction(t, None, a, c)
        assert v.present is True and v.overruled_by is None and "verdict_before_cause" not in v
