"""One loop's work: read, screen, diagnose in full where it pays, score; never raises.

:func:`analyse_loop` is what one Ray task runs (and what a test can call
directly).  The full diagnosis is :func:`valve_gym.diagnosis.diagnose`, called
as a library function; its stiction size ``S``, ``J`` and calibrated
probability are read from the :class:`~valve_gym.diagnosis.DiagnosisResult`
when it reports them (:func:`stiction_numbers`), else left NaN and the message
says so.
"""
from __future__ import annotations

import json
import math
import os
import time
from typing import Any, NamedTuple

from ..diagnosis.plant_choice import resolve_plant
from .actions import evidence_weight, recommend, score
from .result import FleetSettings, LoopResult
from .screen import Screen, screen_recording
from .sources import LoopSource, load_loop

__all__ = ["analyse_loop", "stiction_numbers", "StictionNumbers"]


class StictionNumbers(NamedTuple):
    """What a full diagnosis says about the valve.

    Attributes
    ----------
    verdict : str, ``'yes'``, ``'no'``, ``'undecided'`` or ``'not tested'``
    S, J : float, stick band and slip jump [fraction of stroke] (NaN when not reported)
    p : float, calibrated stiction probability (NaN when not reported)
    note : str, what was not reported
    """

    verdict: str
    S: float
    J: float
    p: float
    note: str


_VERDICTS = {"yes": "yes", "stiction": "yes", "present": "yes", "no": "no", "no stiction": "no", "none": "no",
             "undecided": "undecided", "undetermined": "undecided"}


def _get(obj: Any, key: str):
    if isinstance(obj, dict):
        return obj.get(key)
    return getattr(obj, key, None)


def _num(x) -> float:
    """A number from ``x``: a float, or the ``value``/``estimate`` of a dict or object; else NaN."""
    for _ in range(3):
        if isinstance(x, (int, float)) and not isinstance(x, bool):
            return float(x) if math.isfinite(x) else math.nan
        if x is None:
            return math.nan
        x = next((v for v in (_get(x, "value"), _get(x, "estimate")) if v is not None), None)
    return math.nan


def stiction_numbers(res) -> StictionNumbers:
    """``S``, ``J``, probability and verdict from a DiagnosisResult, whatever of them it reports.

    Looks for (in order) attributes ``stiction_probability``/``S``/``J`` of the result, then keys
    ``probability``/``p_stiction``, ``S``, ``J`` of its ``stiction`` record, then the fitted
    slip-jump parameters (``stiction['parameters']['S']``).
    """
    st = _get(res, "stiction") or {}
    par = _get(st, "parameters") or {}
    p = _num(_get(res, "stiction_probability"))
    for k in ("probability", "p_stiction", "p"):
        if math.isnan(p):
            p = _num(_get(st, k))
    S = _num(_get(res, "S"))
    J = _num(_get(res, "J"))
    if math.isnan(S):
        S, J = _num(_get(st, "S")), _num(_get(st, "J"))
    if math.isnan(S):
        S, J = _num(_get(par, "S")), _num(_get(par, "J"))
    text = _get(st, "verdict")
    present = _get(st, "present")
    if isinstance(text, str) and text.strip().lower() in _VERDICTS:
        verdict = _VERDICTS[text.strip().lower()]
    elif _get(st, "tested") is False:
        verdict = "not tested"
    elif present is None:
        verdict = "undecided"
    else:
        verdict = "yes" if present else "no"
    miss = [n for n, v in (("S", S), ("J", J), ("probability", p)) if math.isnan(v)]
    note = f"{', '.join(miss)} not reported by the diagnosis" if miss else ""
    return StictionNumbers(verdict, S, J, p, note)


def _full(rec, settings: FleetSettings, loop: str):
    from ..diagnosis.diagnose import diagnose
    res = diagnose(rec, plant=settings.plant, actuator=settings.actuator, candidates=settings.candidates,
                   holdout=settings.holdout, effort=settings.effort, seed=settings.seed, jobs=1,
                   search=settings.search, op_lag=settings.op_lag)
    if settings.report_dir:
        from ..diagnosis.report import write_report
        write_report(res, os.path.join(settings.report_dir, loop))
    return res


def _evidence(sc: Screen, sn: StictionNumbers | None, w_src: str, cause=None) -> str:
    o = sc.oscillation
    parts = [o.reason]
    if cause is not None and cause.oscillating:
        p = cause.probabilities
        parts.append(f"cause: {cause.cause} (" + ", ".join(f"{c} {v:.2f}" for c, v in p.items()) + ")")
    if o.present:
        parts.append(f"OP swing {100 * sc.amplitude_op:.1f} % of stroke")
    if sc.horch.verdict not in ("not applicable",) and not math.isnan(sc.horch.phase_index):
        parts.append(f"Horch: {sc.horch.verdict} (index {sc.horch.phase_index:.2f})")
    if sn is not None:
        parts.append(f"model verdict: {sn.verdict}" + (f", p = {sn.p:.2f}" if not math.isnan(sn.p) else "")
                     + (f", S = {100 * sn.S:.1f} %" if not math.isnan(sn.S) else "")
                     + (f", J = {100 * sn.J:.1f} %" if not math.isnan(sn.J) else ""))
        if sn.note:
            parts.append(sn.note)
    parts.append(f"w from {w_src}")
    return "; ".join(parts)


def _cause_fields(cause) -> dict:
    """The cause columns of a loop's row (:class:`~valve_gym.diagnosis.causes.OscillationCause`)."""
    if cause is None:
        return {}
    p = cause.probabilities
    nan = math.nan
    return {"cause": cause.cause, "p_valve": p.get("stiction", nan), "p_tuning": p.get("tuning", nan),
            "p_disturbance": p.get("disturbance", nan), "p_sensor": p.get("sensor", nan),
            "p_saturation": p.get("saturation", nan), "suggested_kc": cause.suggested_Kc_raw,
            "cause_evidence": cause.sentence() if cause.oscillating else "",
            "cause_scores": json.dumps(dict(cause.scores)) if cause.scores else ""}


def _ok_result(src: LoopSource, key: str, loaded, sc: Screen, res, seconds: float, cpu: float,
               cause=None) -> LoopResult:
    rec = loaded.recording
    o = sc.oscillation
    sn = stiction_numbers(res) if res is not None else None
    verdict = sn.verdict if sn else "not tested"
    p = sn.p if sn else math.nan
    if res is not None:
        cause = getattr(res, "cause", None)
    w, w_src = evidence_weight(p, verdict, sc.horch.phase_index)
    if cause is not None and cause.oscillating:
        w, w_src = cause.p_stiction, "probability that the valve causes the oscillation"
    S = sn.S if sn else math.nan
    _, action = recommend("ok", "", o.present, verdict, w, S, sc.amplitude_op, cause)
    effects, rb, rf = "", math.nan, math.nan
    if res is not None:
        effects = ";".join(res.effects) or "none"
        rb, rf = float(res.base.rmse_all), float(res.final.rmse_all)
    return LoopResult(
        loop=src.name, status="ok", message=_evidence(sc, sn, w_src, cause), stiction=verdict, S=S,
        J=sn.J if sn else math.nan, effects=effects, rmse_base=rb, rmse_final=rf, oscillation=o.amplitude,
        seconds=seconds, cpu_seconds=cpu, p_stiction=p, weight=w, score=score(w, sc.amplitude_op, o.present),
        action=action,
        stage="full" if res is not None else "screen", oscillating=o.present, regularity=o.regularity,
        period_s=o.period_s, amplitude_op=sc.amplitude_op, horch=sc.horch.verdict,
        horch_index=sc.horch.phase_index, n=len(rec), dt=float(rec.dt), gaps=len(loaded.gaps),
        notes=loaded.notes, source=src.path, tag=src.tag, key=key, **_cause_fields(cause))


def failed_result(src: LoopSource, key: str, status: str, message: str, seconds: float = 0.0) -> LoopResult:
    """The row of a loop that could not be analysed (``status`` ``'failed'`` or ``'error'``)."""
    _, action = recommend(status, message, False, "not tested", math.nan, math.nan, math.nan)
    return LoopResult(loop=src.name, status=status, message=message, seconds=seconds, action=action,
                      source=src.path, tag=src.tag, key=key)


def analyse_loop(src: LoopSource, settings: FleetSettings, key: str = "") -> LoopResult:
    """Read, screen and (where it oscillates, or ``settings.full``) diagnose one loop.

    Parameters
    ----------
    src : LoopSource
    settings : FleetSettings
    key : str, the loop's resume key (stored in the result)

    Returns
    -------
    LoopResult, status ``'ok'``, ``'failed'`` (bad data: the message names the problem and the fix)
    or ``'error'`` (an internal error: type and message). Never raises an ``Exception``.
    """
    from ..diagnosis.recording import RecordingError

    t0, c0 = time.perf_counter(), time.process_time()
    try:
        loaded = load_loop(src, **settings.load_kw())
        rec = loaded.recording
        sc = screen_recording(rec, resolve_plant(settings.plant, rec.name, rec.columns.get("pv"), rec.op, rec.pv,
                                                 float(rec.dt or 1.0))[0])
        res, cause = None, None
        if settings.full or sc.oscillation.present or position_sticks(rec):
            try:
                res = _full(loaded.recording, settings, src.name)
            except ValueError as e:
                if "takes only" not in str(e):
                    raise
                # a PV of a few levels: no model to fit, but its quantisation is the evidence
                from ..diagnosis.causes import cause_from_data
                cause = cause_from_data(rec)
        return _ok_result(src, key, loaded, sc, res, time.perf_counter() - t0, time.process_time() - c0, cause)
    except (RecordingError, ValueError) as e:
        return failed_result(src, key, "failed", str(e).splitlines()[0] if str(e) else type(e).__name__,
                             time.perf_counter() - t0)
    except Exception as e:  # an internal error must not stop the fleet
        return failed_result(src, key, "error", f"internal error: {type(e).__name__}: {e}",
                             time.perf_counter() - t0)


def position_sticks(rec) -> bool:
    """Whether the loop's recorded valve position shows a sticking stem (the stem test; False without one).

    The screen sends only oscillating loops to the full diagnosis; a sticky valve under a drifting
    load often does not cycle, but where the position is logged the stem test (a fraction of a second)
    reads it directly, and such a loop gets the full diagnosis too.
    """
    if rec.mv is None:
        return False
    from ..diagnosis.stiction.stem import stem_evidence

    return stem_evidence(rec.op, rec.mv, float(rec.dt or 1.0)).verdict == "stiction"
