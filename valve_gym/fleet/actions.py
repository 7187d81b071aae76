r"""Ranking score and recommended action of a loop: the worklist's rules, written once.

Score
-----
A loop's cost of stiction is scored as

.. math:: \text{score} = w \cdot 100\,A_{OP}

with ``A_OP`` the amplitude of the controller output's oscillation (fraction
of stroke, from :func:`valve_gym.fleet.screen.screen_recording`; 0 when the
loop does not oscillate) and ``w`` the stiction evidence weight, 0..1:

* the calibrated stiction probability of the diagnosis when it reports one;
* otherwise the mean of the evidence available: the model-based verdict
  (yes = 1, no = 0; undecided not counted) and Horch's phase index
  (0 even ... 1 odd cross-correlation).  This weight is *not* a calibrated
  probability, and the worklist says which one was used;
* 0.5 when neither exists.

The controller output is on the same 0-100 % scale in every loop, so scores
compare across loops whose PVs have different units; a sticky valve's cycle in
the controller output grows with its stick band (Choudhury, Thornhill & Shah
2005), and the valve travel it drives is what wears the packing.  The PV
amplitude (``oscillation``, PV units) is listed beside it.

Actions
-------
First matching rule of :data:`RULES` (``S``: the diagnosis' stick band; when it
is not reported, the controller-output amplitude ``A_OP`` stands in for it,
since a stiction cycle's OP swing is about the stick band):

==========  ===============================================  =========================================
rule        when                                             action
==========  ===============================================  =========================================
data        status is not ``ok``                             check the data (the message says what)
quiet       no oscillation, no friction found                nothing
inspect     no oscillation, model verdict ``yes``            nothing now; inspect at next shutdown
repair      oscillates, ``w >= 0.67``, ``S >= 5 %``          repair at next shutdown; knocker until then
compensate  oscillates, ``w >= 0.67``, ``S < 5 %``           run the knocker (set from ``S``)
retune      oscillates, ``w <= 0.33``                        retune / look for the disturbance
undecided   oscillates, otherwise                            bump-test the valve (or ``--full``)
==========  ===============================================  =========================================

The compensator named is :data:`COMPENSATOR`, Hägglund's knocker set from the
stiction estimate ``S`` (``valve_gym.agents.load_controller("knocker", S=...)``).  The
rule follows the regulation part of the compensator benchmark
(``docs/benchmark.md``, sticky + severe valves, medians with 95 % CIs): the
knocker removes most of stiction's cost (compensation ratio ``R`` 0.88 [0.79,
0.95], 0.83 on the severe band) at 0.73x the frictionless PI's stem travel,
and keeps ``R`` 0.93 with ``S`` 50 % too high (at 1.65x the travel) and 0.49
with ``S`` 50 % too low; constant reinforcement reaches ``R`` 0.42, two-move
and integral freeze ``R`` < 0, and detuning the PI never pays (``R`` < 0 along
the whole Pareto front), so "retune" is recommended only where the valve is
not the cause.  A severe valve (``S >= 5 %``) is still sent to repair: the
knocker holds it until the shutdown, at more valve travel.

References
----------
.. [1] M. A. A. S. Choudhury, N. F. Thornhill and S. L. Shah, "Modelling valve
   stiction", Control Engineering Practice 13(5), 641-658, 2005.
.. [2] T. Hägglund, "A friction compensator for pneumatic control valves",
   Journal of Process Control 12(8), 897-904, 2002.
"""
from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["Rule", "RULES", "COMPENSATOR", "W_HIGH", "W_LOW", "S_SEVERE", "evidence_weight", "score",
           "recommend"]

#: Evidence weight at and above which the valve is taken as the cause.
W_HIGH = 0.67
#: Evidence weight at and below which the valve is taken as not the cause.
W_LOW = 0.33
#: Stick band [fraction of stroke] from which a valve counts as severe (repair, not compensate).
S_SEVERE = 0.05
#: Compensator recommended until the valve is repaired, and why (docs/benchmark.md, regulation part).
COMPENSATOR = ("Hägglund's knocker",
               "removes most of stiction's regulation cost in the compensator benchmark (R 0.88, 0.83 on "
               "severe valves) at 0.73x the frictionless PI's stem travel; constant reinforcement 0.42, "
               "two-move and integral freeze < 0, a detuned PI < 0")


class Rule(NamedTuple):
    """One row of the action table.

    Attributes
    ----------
    name : str, short name
    when : str, the condition in words
    action : str, the recommendation (``{S}`` is filled in)
    """

    name: str
    when: str
    action: str


#: The action table, first match wins (see the module docstring).
RULES = (
    Rule("data", "status is not ok", "check the data: {message}"),
    Rule("quiet", "no oscillation and no friction found", "nothing"),
    Rule("inspect", "no oscillation, the diagnosis finds friction",
         "nothing now; inspect the valve at the next shutdown (friction found, no cycle today)"),
    Rule("repair", f"oscillates, w >= {W_HIGH}, S >= {S_SEVERE:.0%} of stroke",
         "repair the valve at the next shutdown (stick band {S} of stroke); until then run "
         + COMPENSATOR[0] + " with S = {S}"),
    Rule("compensate", f"oscillates, w >= {W_HIGH}, S < {S_SEVERE:.0%} of stroke",
         "run " + COMPENSATOR[0] + " with the stiction estimate S = {S}; repair the valve when convenient"),
    Rule("cause", "oscillates, and the most probable cause of the oscillation is not the valve "
                  "(valve_gym.diagnosis.causes)",
         "{cause_action}"),
    Rule("retune", f"oscillates, w <= {W_LOW}",
         "retune the controller or find the oscillating disturbance (the valve is not the cause)"),
    Rule("undecided", "oscillates, otherwise",
         "bump-test the valve (or diagnose in full with --full): the evidence is mixed"),
)


def _finite(x) -> bool:
    return x is not None and isinstance(x, (int, float)) and math.isfinite(x)


def evidence_weight(p_stiction: float, verdict: str, horch_index: float) -> tuple[float, str]:
    """Stiction evidence weight ``w`` (0..1) and where it came from (see the module docstring)."""
    if _finite(p_stiction):
        return float(p_stiction), "calibrated probability"
    ev = []
    if verdict in ("yes", "no"):
        ev.append(1.0 if verdict == "yes" else 0.0)
    if _finite(horch_index):
        ev.append(float(horch_index))
    if not ev:
        return 0.5, "no evidence"
    return sum(ev) / len(ev), "mean of " + " and ".join(
        (["model verdict"] if verdict in ("yes", "no") else []) + (["Horch index"] if _finite(horch_index) else []))


def score(weight: float, amplitude_op: float, oscillating: bool) -> float:
    """Ranking score ``w * 100 * A_OP`` [% of stroke]; 0 for a loop that does not oscillate."""
    if not oscillating or not _finite(amplitude_op):
        return 0.0
    return float(weight) * 100.0 * float(amplitude_op)


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def recommend(status: str, message: str, oscillating: bool, verdict: str, weight: float, S: float,
              amplitude_op: float, cause=None) -> tuple[str, str]:
    """The first rule of :data:`RULES` that matches; returns ``(rule name, action text)``.

    Parameters
    ----------
    status, message : str, the loop's status and message
    oscillating : bool
    verdict : str, model-based verdict (``'yes'``, ``'no'``, ...)
    weight : float, evidence weight 0..1
    S : float, stick band [fraction of stroke], NaN when unknown
    amplitude_op : float, controller-output amplitude [fraction of stroke]
    cause : OscillationCause, optional, the cause of the oscillation (:mod:`valve_gym.diagnosis.causes`):
        where it names another cause than the valve, the action follows it (retune with the suggested
        gain, find the upstream source, check the transmitter or the output's limits)
    """
    band = S if _finite(S) else amplitude_op
    band_txt = _pct(S) if _finite(S) else (f"~{_pct(amplitude_op)} (from the OP swing; not estimated)"
                                           if _finite(amplitude_op) else "unknown")
    if status != "ok":
        name = "data"
    elif not oscillating:
        name = "inspect" if verdict == "yes" else "quiet"
    elif cause is not None and getattr(cause, "oscillating", False) and cause.cause != "stiction" \
            and weight < W_HIGH:
        name = "cause"
    elif weight >= W_HIGH:
        name = "repair" if _finite(band) and band >= S_SEVERE else "compensate"
    elif weight <= W_LOW:
        name = "retune"
    else:
        name = "undecided"
    rule = next(r for r in RULES if r.name == name)
    return name, rule.action.format(S=band_txt, message=message,
                                    cause_action=cause.action() if cause is not None else "")
