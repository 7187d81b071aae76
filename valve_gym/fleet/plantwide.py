"""Plant-wide oscillations: loops of a fleet that share an oscillation period (Thornhill et al. 2003).

An oscillation that starts in one loop (a sticky valve, a badly tuned loop) travels through the
process to the loops downstream and upstream of it, which then cycle at the same period for no
fault of their own.  :func:`apply_shared_periods` reads the fleet's oscillating loops after each
has been diagnosed alone: where several share a period (within
:data:`~valve_gym.diagnosis.causes.SHARED_PERIOD`), the loop most likely to be the source -- the one
whose valve is most probably sticking, as Thornhill's nonlinearity ranking picks the most
nonlinear loop -- keeps its cause, and every other loop of the group gets the evidence of an
external disturbance (:meth:`~valve_gym.diagnosis.causes.OscillationCause.with_shared_period`),
which may change its cause and its action (find the upstream source, naming the likely source).

Reference: N.F. Thornhill, B. Huang, H. Zhang, "Detection of multiple oscillations in control
loops", Journal of Process Control 13 (2003) 91-100; N.F. Thornhill, J.W. Cox, M.A. Paulonis,
"Diagnosis of plant-wide oscillation through data-driven analysis and process understanding",
Control Engineering Practice 11 (2003) 1481-1490.
"""
from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import replace

from ..diagnosis.causes import OscillationCause, _softmax, shared_periods
from .actions import W_HIGH, score
from .result import LoopResult

__all__ = ["apply_shared_periods"]


def _cause_of(r: LoopResult) -> OscillationCause | None:
    if not r.cause_scores or r.cause in ("", "none"):
        return None
    try:
        scores = {k: float(v) for k, v in json.loads(r.cause_scores).items()}
    except (ValueError, TypeError, AttributeError):
        return None
    probs = _softmax(scores)
    return OscillationCause(True, r.period_s, probs, max(probs, key=lambda c: probs[c]), (), scores=scores)


def apply_shared_periods(results: Sequence[LoopResult]) -> list[LoopResult]:
    """The fleet's results with the shared-period evidence added to the loops that receive an oscillation.

    Parameters
    ----------
    results : sequence of LoopResult
        One per loop, each diagnosed alone.

    Returns
    -------
    list of LoopResult, same order; a changed row's ``cause``, probabilities, ``weight``, ``score``,
    ``action`` and ``cause_evidence`` say so.
    """
    causes = {r.loop: _cause_of(r) for r in results if r.status == "ok" and r.oscillating}
    causes = {k: v for k, v in causes.items() if v is not None}
    groups = shared_periods({k: float(next(r.period_s for r in results if r.loop == k)) for k in causes})
    out = []
    for r in results:
        others = groups.get(r.loop, ())
        c = causes.get(r.loop)
        if c is None or not others:
            out.append(r)
            continue
        group = (r.loop,) + tuple(others)
        source = max(group, key=lambda k: causes[k].p_stiction)
        if source == r.loop and c.cause == "stiction":
            out.append(replace(r, cause_evidence=(r.cause_evidence + f" It shares its period with "
                                                  f"{', '.join(others[:4])}: the likely source of a plant-wide "
                                                  f"oscillation.").strip()))
            continue
        c2 = c.with_shared_period(others)
        p = c2.probabilities
        w = c2.p_stiction
        action = r.action
        if c2.cause != "stiction" and c2.cause != c.cause or (c2.cause == "disturbance" and w < W_HIGH):
            action = c2.action() + (f"; likely source: {source}" if source != r.loop else "")
        out.append(replace(
            r, cause=c2.cause, p_valve=p["stiction"], p_tuning=p["tuning"], p_disturbance=p["disturbance"],
            p_sensor=p["sensor"], p_saturation=p["saturation"], weight=w,
            score=score(w, r.amplitude_op, r.oscillating) if math.isfinite(r.amplitude_op) else r.score,
            action=action, cause_scores=json.dumps(dict(c2.scores)),
            cause_evidence=(r.cause_evidence + " " + c2.evidence[-1].statement).strip()))
    return out
