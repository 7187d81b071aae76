"""The cause of a loop's oscillation: valve stiction, aggressive tuning, an external disturbance, a sensor fault.

A loop that oscillates does so for one of a few reasons (Thornhill & Horch 2007; Jelali 2013, ch. 2):
a sticky valve (a limit cycle through the friction), a controller tuned too tightly (the loop's own
mode, near its stability limit), an oscillating disturbance entering from outside the loop (through
the load or the set point), or a sensor or actuator fault (a quantised PV that integral action hunts
between levels; an output sitting at a limit, where integral wind-up makes the loop cycle).
:func:`oscillation_cause` reads each from its published evidence and turns them into probabilities:

* **stiction** -- the combined stiction assessment (:mod:`.stiction`: the OP-PV shape and phase
  tests, the friction fits), as its log-odds;
* **tuning** -- the gain margin of the loop implied by the fitted process model and the PI law
  fitted to the recorded output (velocity form, least squares): a margin below about 1.5, with the
  oscillation at the period where the loop's phase is -180 deg, is the loop's own mode
  (Åström & Hägglund 2006, ch. 4); the suggested gain is the one that gives a margin of 2;
* **disturbance** -- an oscillation in the set point at the same period (imposed from outside the
  loop: a cascade master, an upstream unit), an oscillation of the PV that the fitted model does not
  produce from the output (it enters through the load), a linear, sinusoidal oscillation (no
  quadratic phase coupling: Choudhury et al. 2004), and, in a fleet, other loops sharing the period
  (Thornhill et al. 2003: a plant-wide oscillation comes from one source and spreads);
* **sensor** -- a PV oscillating over only a few quantisation steps of its transmitter;
* **saturation** -- an output at 0 or 100 % of its stroke for part of the record.

Each cause's score is a prior plus the pull of each piece of evidence (log-odds); the probabilities
are the scores' softmax.  The weights below were set from these arguments before any validation
score was read (``docs/causes.md``); they are not fitted.  The result is a frozen
:class:`OscillationCause`, built once per record and shared by the JSON, the report and the
worklist.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..metrics import crest_factor
from ..oscillation import detect_oscillation
from .stiction._base import bandpass, oscillation

__all__ = ["CAUSES", "CauseEvidence", "OscillationCause", "cause_from_data", "estimate_pi", "gain_margin",
           "oscillation_cause", "shared_periods"]

#: The causes, in the order reported.
CAUSES = ("stiction", "tuning", "disturbance", "sensor", "saturation")
#: Words for each cause.
CAUSE_WORDS = {"stiction": "valve stiction", "tuning": "aggressive tuning",
               "disturbance": "external oscillating disturbance", "sensor": "sensor / quantisation fault",
               "saturation": "output saturation (OP at a limit)"}
#: Prior log-odds of each cause on an oscillating loop before its evidence (stiction: its assessment's own).
PRIOR = {"tuning": -1.0, "disturbance": -0.5, "sensor": -3.0, "saturation": -3.0}
#: Gain margin below which the loop is near its own stability limit.
GM_LOW = 1.5
#: Gain margin the suggested controller gain aims at (Åström & Hägglund: 2..5; 2 keeps the loop fast).
GM_TARGET = 2.0
#: Relative distance of the oscillation period from the loop's -180 deg period that counts as a match.
PERIOD_MATCH = 0.35
#: Ratio of the set point's to the PV's oscillation (band-passed RMS) above which the oscillation is imposed.
SP_RATIO = 0.3
#: Share of the PV's oscillation (band-passed RMS) that the fitted model leaves unexplained, above which
#: the oscillation enters through the load.
UNEXPLAINED = 0.6
#: PV oscillation amplitude (half peak-to-peak), in quantisation steps, at or below which the sensor's
#: resolution drives the cycle.
QUANT_STEPS = 3.0
#: Share of the samples with the output at a limit (within 0.5 % of 0 or 100 % of the stroke) that counts.
SATURATED = 0.05
#: Miao & Seborg's ACF decay ratio of a lightly damped loop mode (tuning): a damping ratio of 0.02..0.11
#: decays the ACF by exp(-2 pi zeta / sqrt(1 - zeta^2)) = 0.9..0.5 per cycle; and of a sustained cycle.
DECAY_MODE = (0.5, 0.9)
DECAY_SUSTAINED = 0.95
#: Band-passed crest factor from which the oscillation counts as noise-driven (narrow-band Gaussian noise:
#: about 3 over a long record; a sine 1.41, a triangle 1.73).
CREST_NOISE = 2.4
#: Thornhill's regularity from which the oscillation counts as strictly periodic.
REGULARITY_PERIODIC = 20.0
#: Relative difference of two loops' periods for them to share one (Thornhill et al. 2003 use 10 %...20 %).
SHARED_PERIOD = 0.15


@dataclass(frozen=True)
class CauseEvidence:
    """One piece of evidence for (or against) one cause.

    Attributes
    ----------
    cause : str, one of :data:`CAUSES`
    pull : float, change of the cause's log-odds score
    statement : str, the evidence in words
    """

    cause: str
    pull: float
    statement: str


@dataclass(frozen=True)
class OscillationCause:
    """Why a loop oscillates: a probability per cause, the evidence in words, the action it calls for.

    Attributes
    ----------
    oscillating : bool, whether the control error oscillates regularly (else no cause is read)
    period_s : float, oscillation period [s] (nan when not oscillating)
    probabilities : mapping of cause -> probability (sums to 1; empty when not oscillating)
    cause : str, the most probable cause, or ``'none'`` when the loop does not oscillate
    evidence : tuple of CauseEvidence
    gain_margin : float, of the fitted loop (nan when it could not be read; inf: no phase crossover)
    period_180_s : float, period at which the fitted loop's phase is -180 deg [s]
    controller : dict, the PI law fitted to the output: ``Kc`` [stroke per PV unit], ``Ti`` [s], ``r2``
    suggested_Kc : float, gain for a margin of :data:`GM_TARGET` [stroke per PV unit] (nan unless tuning)
    suggested_Kc_raw : float, the same in the output's raw units per PV unit (``op_range`` span)
    shared_with : tuple of str, other loops of a fleet oscillating at the same period
    """

    oscillating: bool
    period_s: float
    probabilities: Mapping[str, float]
    cause: str
    evidence: tuple[CauseEvidence, ...]
    gain_margin: float = math.nan
    period_180_s: float = math.nan
    controller: Mapping[str, float] = field(default_factory=dict)
    suggested_Kc: float = math.nan
    suggested_Kc_raw: float = math.nan
    shared_with: tuple[str, ...] = ()
    scores: Mapping[str, float] = field(default_factory=dict)

    @property
    def p_stiction(self) -> float:
        """Probability of valve stiction (nan when the loop does not oscillate)."""
        return float(self.probabilities.get("stiction", math.nan))

    def sentence(self) -> str:
        """The cause and its probability, with the evidence for it, in words."""
        if not self.oscillating:
            return "The loop does not oscillate regularly: no cause of oscillation is read."
        p = self.probabilities
        ranked = sorted(CAUSES, key=lambda c: -p[c])
        head = (f"The oscillation (period {self.period_s:.3g} s) is most likely {CAUSE_WORDS[ranked[0]]} "
                f"(p = {p[ranked[0]]:.2f}; " + ", ".join(f"{c} {p[c]:.2f}" for c in ranked[1:]) + ").")
        why = [e.statement for e in self.evidence if e.cause == ranked[0] and e.pull > 0]
        return head + (" Evidence: " + " ".join(why) if why else "")

    def action(self) -> str:
        """What to do, following the most probable cause."""
        if not self.oscillating:
            return ""
        c = self.cause
        if c == "stiction":
            return "repair the valve (stiction: service the packing/positioner, or a valve test first)"
        if c == "tuning":
            if math.isfinite(self.suggested_Kc_raw) and math.isfinite(self.controller.get("Kc", math.nan)):
                return (f"retune: lower the controller gain to about Kc = {self.suggested_Kc_raw:.3g} "
                        f"(now about {self.controller['Kc_raw']:.3g}, output units per PV unit; gain margin "
                        f"{self.gain_margin:.2f} -> {GM_TARGET:g})")
            return "retune: lower the controller gain (the loop is near its stability limit)"
        if c == "disturbance":
            if self.shared_with:
                return (f"find the upstream source: the same period is in {', '.join(self.shared_with[:4])}"
                        + (" ..." if len(self.shared_with) > 4 else "") + "; the loop is not the cause")
            return "find the upstream source of the oscillating disturbance; the loop is not the cause"
        if c == "sensor":
            return "check the transmitter: its resolution drives the cycle (finer PV, or a deadband in the controller)"
        return "check the valve's size and the output limits: the output sits at a limit (integral wind-up)"

    def with_shared_period(self, others: Sequence[str], pull: float = 2.0) -> OscillationCause:
        """A copy with the evidence that ``others`` (loops of the same plant) oscillate at the same period."""
        if not self.oscillating or not others:
            return self
        ev = CauseEvidence("disturbance", pull,
                           f"{len(others)} other loop(s) of the plant oscillate at the same period "
                           f"({', '.join(list(others)[:4])}): a plant-wide oscillation spreads from one source "
                           f"(Thornhill et al. 2003).")
        scores = dict(self.scores)
        scores["disturbance"] = scores.get("disturbance", 0.0) + pull
        probs = _softmax(scores)
        return replace(self, evidence=self.evidence + (ev,), scores=scores, probabilities=probs,
                       cause=max(probs, key=lambda c: probs[c]), shared_with=tuple(others))

    def to_dict(self) -> dict:
        """JSON-ready dict (nan and inf become None)."""
        def f(x):
            x = float(x)
            return x if math.isfinite(x) else None
        return {"oscillating": self.oscillating, "period_s": f(self.period_s), "cause": self.cause,
                "cause_words": CAUSE_WORDS.get(self.cause, "no oscillation"),
                "probabilities": {c: f(p) for c, p in self.probabilities.items()},
                "evidence": [{"cause": e.cause, "pull": f(e.pull), "statement": e.statement} for e in self.evidence],
                "gain_margin": f(self.gain_margin), "period_180_s": f(self.period_180_s),
                "controller": {k: f(v) for k, v in self.controller.items()},
                "suggested_Kc": f(self.suggested_Kc), "suggested_Kc_raw": f(self.suggested_Kc_raw),
                "shared_with": list(self.shared_with), "action": self.action(), "summary": self.sentence()}


def _softmax(scores: Mapping[str, float]) -> dict[str, float]:
    m = max(scores.values())
    e = {c: math.exp(s - m) for c, s in scores.items()}
    z = sum(e.values())
    return {c: e[c] / z for c in CAUSES if c in e}


# --------------------------------------------------------------------------- pieces
def estimate_pi(op, pv, sp, dt: float) -> dict[str, float]:
    """The PI law that produced the recorded output: ``Kc`` [stroke per PV unit], ``Ti`` [s], ``r2``.

    Velocity form ``du[k] = Kc (e[k] - e[k-1]) + Kc dt / Ti e[k]`` with ``e = sp - pv`` (the PV's
    mean where no set point is recorded), fitted by least squares with the error of the same sample
    and of the one before (the recorder's pairing); the pairing that fits better is kept.  ``Kc`` is
    given as a magnitude (its sign is the controller's action).
    """
    u = np.asarray(op, float)
    y = np.asarray(pv, float)
    r = np.asarray(sp, float) if sp is not None else np.full_like(y, float(np.mean(y)))
    e = r - y
    du = np.diff(u)
    best = {"Kc": math.nan, "Ti": math.nan, "r2": 0.0}
    for lag in (0, 1):
        ee = e[1 - lag:len(e) - lag] if lag else e[1:]
        ep = e[:len(e) - 1 - lag] if lag else e[:-1]
        d = du[lag:] if lag else du
        m = min(len(d), len(ee), len(ep))
        d, ee, ep = d[-m:], ee[-m:], ep[-m:]
        X = np.column_stack([ee - ep, ee])
        if m < 10 or not np.all(np.isfinite(X)):
            continue
        coef, *_ = np.linalg.lstsq(X, d, rcond=None)
        res = d - X @ coef
        tot = float(np.sum((d - d.mean()) ** 2))
        r2 = 1.0 - float(res @ res) / tot if tot > 0 else 0.0
        kc, ki = float(coef[0]), float(coef[1])
        if r2 > best["r2"] and kc != 0.0:
            ti = kc * dt / ki if ki != 0.0 and np.sign(ki) == np.sign(kc) else math.inf
            best = {"Kc": abs(kc), "Ti": ti, "r2": r2}
    return best


def _process_response(physical: Mapping[str, float], plant: str, dt: float):
    """``|K| G0(jw)`` of the fitted process (valve position to PV), with its dead time and 1.5 samples of delay.

    The gain's magnitude only: the controller acts against the process's sign (negative feedback).
    """
    theta = float(physical.get("dead_time.theta", 0.0)) + 1.5 * dt      # the sample's delay and the hold
    if plant == "first_order" and "process.K" in physical:
        K, T = abs(float(physical["process.K"])), float(physical["process.T"])
        return lambda w: K / (1j * w * T + 1.0) * np.exp(-1j * w * theta)
    if plant == "integrating" and "process.q_max" in physical:
        k = abs(float(physical["process.q_max"])) / float(physical.get("process.area", 1.0))
        return lambda w: k / (1j * w) * np.exp(-1j * w * theta)
    return None


def gain_margin(physical: Mapping[str, float], plant: str, Kc: float, Ti: float,
                dt: float) -> tuple[float, float]:
    """Gain margin of the loop (fitted process with the PI law ``Kc``, ``Ti``) and its -180 deg period [s].

    Returns ``(inf, nan)`` where the phase stays above -180 deg up to the Nyquist frequency and
    ``(nan, nan)`` where the process model is not one of ``'first_order'``, ``'integrating'``.
    """
    G = _process_response(physical, plant, dt)
    if G is None or not (math.isfinite(Kc) and Kc > 0):
        return math.nan, math.nan
    w = np.geomspace(1e-4 / dt, math.pi / dt, 4000)
    ti = Ti if math.isfinite(Ti) and Ti > 0 else math.inf
    C = Kc * (1.0 + (0.0 if math.isinf(ti) else 1.0 / (1j * w * ti)))
    Lc = C * G(w)
    L = np.abs(Lc)
    ph = np.unwrap(np.angle(Lc))
    ph = ph - 2.0 * math.pi * round(float(ph[0]) / (2.0 * math.pi) + (0.5 if plant == "integrating" else 0.25))
    cross = np.flatnonzero((ph[:-1] > -math.pi) & (ph[1:] <= -math.pi))
    if cross.size == 0:
        return math.inf, math.nan
    i = int(cross[0])
    f = (ph[i] + math.pi) / (ph[i] - ph[i + 1])
    w180 = w[i] * (w[i + 1] / w[i]) ** f
    mag = float(np.exp(np.log(L[i]) + f * (np.log(L[i + 1]) - np.log(L[i]))))
    return (1.0 / mag if mag > 0 else math.inf), 2.0 * math.pi / w180


def _get(x, key: str):
    """``x[key]`` of a dict or ``x.key`` of an object (None if absent)."""
    return x.get(key) if isinstance(x, Mapping) else getattr(x, key, None)


def _band_rms(x: np.ndarray, period: float) -> float:
    return float(np.std(bandpass(np.asarray(x, float), period)))


def _quantisation(pv: np.ndarray) -> tuple[float, int]:
    """The PV's quantisation step (its smallest common change) and its number of distinct values."""
    levels = np.unique(pv)
    if levels.size < 2:
        return math.nan, int(levels.size)
    d = np.abs(np.diff(pv))
    d = d[d > 1e-12 * max(1.0, float(np.max(np.abs(pv))))]
    if d.size == 0:
        return math.nan, int(levels.size)
    q = float(np.min(d))
    multiple = np.abs(d / q - np.round(d / q)) < 0.02
    if levels.size > max(40, len(pv) // 10) or np.mean(multiple) < 0.95:
        return math.nan, int(levels.size)           # not on a grid: a continuous signal
    return q, int(levels.size)


def _at_limit(op: np.ndarray, span_known: bool) -> tuple[float, str]:
    """Share of samples with the output at a limit, and which limit."""
    if span_known:
        lo, hi = float(np.mean(op <= 0.005)), float(np.mean(op >= 0.995))
        return (hi, "its maximum (100 %)") if hi >= lo else (lo, "its minimum (0 %)")
    top, bot = float(np.max(op)), float(np.min(op))
    hi = float(np.mean(op >= top - 1e-9 * max(1.0, abs(top))))
    lo = float(np.mean(op <= bot + 1e-9 * max(1.0, abs(bot))))
    return (hi, "the top of its range") if hi >= lo else (lo, "the bottom of its range")


def _tuning_evidence(u, y, s, dt: float, period: float, *, plant: str, physical, op_span: float,
                     ev: list[CauseEvidence], scores: dict[str, float]):
    """Aggressive tuning: the gain margin of the fitted loop and its -180 deg period (adds to ``ev``, ``scores``)."""
    ctrl = estimate_pi(u, y, s, dt)
    gm, p180 = math.nan, math.nan
    if physical is not None and math.isfinite(ctrl["Kc"]):
        gm, p180 = gain_margin(physical, plant, ctrl["Kc"], ctrl["Ti"], dt)
    ctrl = {**ctrl, "Kc_raw": ctrl["Kc"] * op_span}
    T_s = period * dt
    suggested = math.nan
    if math.isfinite(gm) and ctrl["r2"] >= 0.3:
        match = math.isfinite(p180) and abs(T_s / p180 - 1.0) <= PERIOD_MATCH
        if gm < GM_LOW and match:
            pull = 3.0 + (1.0 if gm < 1.2 else 0.0)
            ev.append(CauseEvidence("tuning", pull,
                                    f"The fitted loop (process model and the PI law fitted to the output, Kc "
                                    f"{ctrl['Kc']:.3g} stroke/PV unit, Ti {ctrl['Ti']:.3g} s, R2 {ctrl['r2']:.2f}) "
                                    f"has a gain margin of {gm:.2f}, and it cycles at {T_s:.3g} s, the period where "
                                    f"its phase is -180 deg ({p180:.3g} s): the loop's own mode."))
            scores["tuning"] += pull
        elif gm < GM_LOW:
            ev.append(CauseEvidence("tuning", 1.0,
                                    f"The fitted loop has a small gain margin ({gm:.2f}), but its -180 deg period "
                                    f"({p180:.3g} s) is not the oscillation's ({T_s:.3g} s)."))
            scores["tuning"] += 1.0
        elif gm > 2.5:
            ev.append(CauseEvidence("tuning", -1.5,
                                    f"The fitted loop has a comfortable gain margin ({gm:.2f}): not a tuning "
                                    f"oscillation."))
            scores["tuning"] -= 1.5
        if gm < GM_LOW:
            suggested = ctrl["Kc"] * gm / GM_TARGET
    elif physical is not None:
        ev.append(CauseEvidence("tuning", 0.0, f"The PI law could not be read from the output (R2 "
                                               f"{ctrl['r2']:.2f}): no gain margin."))
    e = s - y if s is not None else y - float(np.mean(y))
    _noise_driven_evidence(e, dt, period, ev, scores)
    return ctrl, gm, p180, suggested


def _noise_driven_evidence(e, dt: float, period: float, ev: list[CauseEvidence],
                           scores: dict[str, float]) -> None:
    """A lightly damped mode of a linear loop, or a sustained cycle; a periodic source.

    A loop tuned too tightly is a linear system near its stability limit: noise and load excite its
    mode, whose autocorrelation decays from cycle to cycle (Miao & Seborg's decay ratio in
    :data:`DECAY_MODE`) and whose amplitude waxes and wanes like narrow-band noise (band-passed crest
    factor near 3; a steady cycle has 1.4..1.7).  The two read the same property, so they count once:
    +2 for tuning when both say so, +1 when one does.  A limit cycle or a sustained external oscillation
    keeps its amplitude (decay ratio near 1).  A periodic external source (rotating equipment, an
    upstream batch cycle) is strictly periodic: Thornhill's regularity far above the threshold of 1.
    """
    acf = detect_oscillation(e, dt, "benchmark")
    R = float(acf.decay_ratio)
    cf = float(crest_factor(bandpass(np.asarray(e, float), period)))
    damped = math.isfinite(R) and DECAY_MODE[0] <= R <= DECAY_MODE[1]
    noisy = math.isfinite(cf) and cf >= CREST_NOISE
    if damped or noisy:
        pull = 2.0 if damped and noisy else 1.0
        said = []
        if damped:
            said.append(f"its autocorrelation decays from cycle to cycle (Miao & Seborg's decay ratio {R:.2f})")
        if noisy:
            said.append(f"its amplitude waxes and wanes (band-passed crest factor {cf:.2f}; a steady cycle has "
                        f"1.4..1.7)")
        ev.append(CauseEvidence("tuning", pull,
                                "The oscillation is noise-driven: " + " and ".join(said) + ": a lightly damped mode "
                                "of a linear loop, excited by noise and load, not a sustained cycle."))
        scores["tuning"] += pull
        scores["disturbance"] -= pull / 2.0
    elif math.isfinite(R) and R >= DECAY_SUSTAINED:
        ev.append(CauseEvidence("tuning", -1.0,
                                f"The oscillation is sustained (decay ratio {R:.2f}): a limit cycle or a sustained "
                                f"disturbance, not a damped mode of a linear loop."))
        scores["tuning"] -= 1.0
    osc = oscillation(e)
    if osc.present and osc.regularity >= REGULARITY_PERIODIC:
        ev.append(CauseEvidence("disturbance", 1.5,
                                f"The oscillation is strictly periodic (regularity {osc.regularity:.0f}, threshold 1): "
                                f"a periodic source, not the irregular cycle of a noisy loop."))
        scores["disturbance"] += 1.5


def _disturbance_evidence(y, s, period: float, y_model, *, evidence, ev: list[CauseEvidence],
                          scores: dict[str, float]) -> None:
    """External disturbance: the set point, the PV's oscillation the model leaves, linearity."""
    pv_band = _band_rms(y, period)
    if s is not None and np.ptp(s) > 0:
        ratio = _band_rms(s, period) / pv_band if pv_band > 0 else 0.0
        if ratio >= SP_RATIO:
            ev.append(CauseEvidence("disturbance", 3.0,
                                    f"The set point oscillates at the same period ({100 * ratio:.0f} % of the PV's "
                                    f"swing): the oscillation is imposed from outside the loop (a cascade master "
                                    f"or an upstream unit)."))
            scores["disturbance"] += 3.0
    if y_model is not None and pv_band > 0:
        un = _band_rms(y - np.asarray(y_model, float), period) / pv_band
        if un >= UNEXPLAINED:
            ev.append(CauseEvidence("disturbance", 1.5,
                                    f"The fitted model (friction included) reproduces little of the PV's "
                                    f"oscillation from the output ({100 * (1 - min(un, 1.0)):.0f} % explained): "
                                    f"it enters through the load."))
            scores["disturbance"] += 1.5
        elif un <= 0.4:
            ev.append(CauseEvidence("disturbance", -1.0,
                                    f"The fitted model reproduces the PV's oscillation from the output "
                                    f"({100 * (1 - un):.0f} % explained): it passes through the valve."))
            scores["disturbance"] -= 1.0
    bic = next((x for x in evidence if _get(x, "method") == "bicoherence"), None)
    if bic is not None and _get(bic, "applicable") and (_get(bic, "reliability") or 0.0) > 0.3:
        if _get(bic, "verdict") == "no stiction":
            ev.append(CauseEvidence("disturbance", 1.0,
                                    "The oscillation is linear (no quadratic phase coupling in the bicoherence, "
                                    "Choudhury et al. 2004): a sinusoidal disturbance or a tuning mode, not a "
                                    "friction limit cycle."))
            scores["disturbance"] += 1.0
            scores["tuning"] += 0.5


def _fault_evidence(u, y, period: float, span_known: bool, ev: list[CauseEvidence],
                    scores: dict[str, float]) -> None:
    """Sensor quantisation and an output at a limit."""
    q, nlev = _quantisation(y)
    if math.isfinite(q):
        amp = 0.5 * float(np.ptp(bandpass(y, period)))
        steps = amp / q
        if steps <= QUANT_STEPS:
            pull = 5.0 if steps <= 1.5 else 3.5
            ev.append(CauseEvidence("sensor", pull,
                                    f"The PV takes only {nlev} levels {q:.3g} apart, and it oscillates over "
                                    f"{steps:.1f} of those steps: the transmitter's resolution drives the cycle."))
            scores["sensor"] += pull
    # ---- saturation: output at a limit
    share, where = _at_limit(u, span_known)
    if share >= SATURATED and (span_known or share >= 2 * SATURATED):
        pull = 5.0 if share >= 3 * SATURATED else 3.5
        ev.append(CauseEvidence("saturation", pull,
                                f"The output sits at {where} for {100 * share:.0f} % of the record: it cannot "
                                f"act further, and integral wind-up makes the loop cycle."))
        scores["saturation"] += pull
        scores["tuning"] -= 1.0
        keep = max(0.0, 1.0 - share / (3 * SATURATED))
        if scores["stiction"] > 0.0:
            ev.append(CauseEvidence("stiction", -scores["stiction"] * (1.0 - keep),
                                    f"The shape tests assume an output free to move; at a limit for "
                                    f"{100 * share:.0f} % of the record their evidence counts "
                                    f"{100 * keep:.0f} %."))
            scores["stiction"] *= keep


def oscillation_cause(op, pv, dt: float, *, sp=None, plant: str = "first_order",
                      p_stiction: float = math.nan, physical: Mapping[str, float] | None = None, y_model=None,
                      evidence: Sequence = (), op_span: float = 1.0, span_known: bool = True) -> OscillationCause:
    """Probabilities of the causes of the oscillation of one loop, each with its evidence in words.

    Parameters
    ----------
    op : array_like, shape (n,)
        Controller output, fraction of stroke (0..1).
    pv : array_like, shape (n,)
        Process variable, any units.
    dt : float
        Sample time [s].
    sp : array_like, shape (n,), optional
        Set point [PV units].
    plant : str
        The process model fitted (``'first_order'``, ``'integrating'``, ...).
    p_stiction : float
        The combined stiction assessment's probability (nan: no assessment; read as 0.5).
    physical : mapping, optional
        The fitted base model's parameters (:attr:`~valve_gym.diagnosis.fit.FitResult.physical`).
    y_model : array_like, shape (n,), optional
        The fitted model's free-run PV from the output (its friction included).
    evidence : sequence of :class:`~valve_gym.diagnosis.stiction.Evidence`
        The stiction methods' readings (the bicoherence test's is used).
    op_span : float
        The output's raw span (``op_range[1] - op_range[0]``), for the suggested gain in raw units.
    span_known : bool
        Whether the output's range is its stroke (percent or 0..1), so that a limit can be read.

    Returns
    -------
    OscillationCause
        Built once; its probabilities, evidence and action are what the JSON, the report and
        the worklist show.
    """
    u = np.asarray(op, float)
    y = np.asarray(pv, float)
    s = None if sp is None else np.asarray(sp, float)
    e = (s - y) if s is not None else (y - float(np.mean(y)))
    osc = oscillation(e)
    if not osc.present:
        osc_pv = oscillation(y)
        if not osc_pv.present:
            return OscillationCause(False, math.nan, {}, "none", ())
        osc = osc_pv
    period = float(osc.period_samples)
    ev: list[CauseEvidence] = []
    scores = {c: PRIOR.get(c, 0.0) for c in CAUSES}
    # ---- stiction: the combined assessment's log-odds
    p = p_stiction if math.isfinite(p_stiction) else 0.5
    p = min(max(p, 0.02), 0.98)
    scores["stiction"] = math.log(p / (1.0 - p))
    ev.append(CauseEvidence("stiction", scores["stiction"],
                            f"The stiction methods combined (OP-PV shape and phase tests, friction fits) give "
                            f"p = {p:.2f} that the valve sticks."))
    ctrl, gm, p180, suggested = _tuning_evidence(u, y, s, dt, period, plant=plant, physical=physical,
                                                 op_span=op_span, ev=ev, scores=scores)
    _disturbance_evidence(y, s, period, y_model, evidence=evidence, ev=ev, scores=scores)
    _fault_evidence(u, y, period, span_known, ev, scores)
    T_s = period * dt
    probs = _softmax(scores)
    return OscillationCause(True, T_s, probs, max(probs, key=lambda c: probs[c]), tuple(ev), gm, p180, ctrl,
                            suggested, suggested * op_span if math.isfinite(suggested) else math.nan, (), scores)


def cause_from_data(rec) -> OscillationCause:
    """The cause of a recording's oscillation from its data alone, where no model can be fitted to it.

    A PV that takes only a few values (a coarsely quantised transmitter) leaves the process model
    nothing to identify (:func:`~valve_gym.diagnosis.diagnose.diagnose` refuses it), but the
    quantisation itself, the output's limits and the set point are still read; the stiction
    evidence counts as undecided (p = 0.5) and no gain margin is read.

    Parameters
    ----------
    rec : Recording
    """
    said = tuple(rec.notes) + tuple(rec.repairs)
    return oscillation_cause(rec.op, rec.pv, float(rec.dt or 1.0), sp=rec.sp,
                             op_span=float(rec.op_range[1] - rec.op_range[0]),
                             span_known=not any("OP span unknown" in x for x in said))


def shared_periods(periods: Mapping[str, float], tol: float = SHARED_PERIOD) -> dict[str, tuple[str, ...]]:
    """For each loop, the other loops whose oscillation period lies within ``tol`` of its own.

    ``periods``: loop name -> period [s] (nan or missing for loops that do not oscillate).
    """
    ok = {k: v for k, v in periods.items() if isinstance(v, float) and math.isfinite(v) and v > 0}
    out: dict[str, tuple[str, ...]] = {}
    for k, v in ok.items():
        out[k] = tuple(sorted(o for o, w in ok.items() if o != k and abs(w - v) <= tol * max(v, w)))
    return out
