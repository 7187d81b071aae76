"""The friction verdict of a diagnosis: typed, frozen, decided once.

:func:`decide_friction` reads the model-based friction tests (:class:`FreeRunTest`,
:class:`KStepTest`), the methods combined (:class:`~.stiction.StictionAssessment`, with the stem
test where the valve's position is recorded) and the cause of an oscillation
(:class:`~.causes.OscillationCause`), and returns one :class:`FrictionVerdict`.  Nothing edits it
afterwards.  It holds numbers, flags and short codes only; its paragraph in words is written by
:func:`~.explain.explain_friction`, and :meth:`FrictionVerdict.to_dict` gives the JSON keys of
``stiction`` in the diagnosis JSON (with that paragraph under ``explanation``).

A :class:`FrictionVerdict` also reads like the JSON's ``stiction`` object (a read-only mapping:
``verdict["present"]``, ``verdict.get("kstep_delta_ic")``), so that scripts written against the
JSON keys read a result in memory the same way.
"""
from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal

import numpy as np

from .causes import OscillationCause
from .locate import ConditionStat
from .select import SelectionRule
from .stiction import Evidence, StictionAssessment
from .stiction.combine import public_present
from .stiction.hammerstein import SEIZED_TRAVEL, friction_moves

__all__ = ["FreeRunTest", "KStepTest", "FrictionVerdict", "decide_friction", "model_based_readings",
           "frozen_position", "json_ready", "finite_or_none", "UNITS"]

#: Units of the friction parameters and bands (``stiction.units`` of the JSON).
UNITS = {"S": "fraction of stroke", "J": "fraction of stroke", "z_max": "s (integrated error)",
         "e_dead": "fraction of stroke", "dead_band": "fraction of stroke", "band": "fraction of stroke"}

#: Where the public verdict comes from: the methods combined with the model-based tests, the recorded
#: valve position (the stem test), or a position that never moved read with the process model.
VerdictSource = Literal["methods", "stem", "stem+model"]
#: What a recorded position that never moved says (:func:`frozen_position`).
FrozenPosition = Literal["seized", "short_travel", "frozen_signal"]


def finite_or_none(x):
    """``float(x)``, or None where ``x`` is None, nan or inf (for JSON)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def json_ready(o: Any) -> Any:
    """``o`` made JSON-safe: numpy scalars and arrays to Python, nan and inf to None, mappings to dicts."""
    if isinstance(o, Mapping):
        return {str(k): json_ready(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_ready(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return finite_or_none(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, np.ndarray):
        return json_ready(o.tolist())
    return o


@dataclass(frozen=True)
class FreeRunTest:
    """Friction against frictionless models, each simulated free-running over the whole record.

    Attributes
    ----------
    parameters : mapping, the best friction model's friction: ``model`` (``'slip_jump'`` or ``'valve'``)
        and ``S``, ``J``, ``band`` (slip-jump) or ``z_max`` [s], ``e_dead``, ``dead_band``, ``band``
        (the paper's valve); bands in fractions of stroke
    delta_ic : float, information-criterion change from the best frictionless model to the best friction model
    significant : bool, ``delta_ic`` below ``-rule.ic_margin``
    band : float, the friction band of the best friction model [fraction of stroke]
    slips : int, how often that model's valve moves over the record
    band_needed : float, the band that matters in this loop [fraction of stroke] (``rule.band_needed``)
    op_working_range : float, the controller output's 2-98 % range [fraction of stroke]
    n_eff : float, effective samples of the criterion
    frictionless_model, frictionless_rmse : str, float, the best frictionless model and its RMSE [PV units]
    friction_rmse : float, RMSE of the best friction model [PV units]
    compared : mapping of model label -> RMSE [PV units], every fit of the test
    lag_alt : tuple of str, the delaying effects (dead time, sensor lag) of the best frictionless model
        that the final model has not
    reversal : ConditionStat or None, the residual at the output's reversals (base model)
    rule : SelectionRule, the thresholds it was judged with
    """

    parameters: Mapping[str, Any]
    delta_ic: float
    significant: bool
    band: float
    slips: int
    band_needed: float
    op_working_range: float
    n_eff: float
    frictionless_model: str
    frictionless_rmse: float
    friction_rmse: float
    compared: Mapping[str, float]
    lag_alt: tuple[str, ...] = ()
    reversal: ConditionStat | None = None
    rule: SelectionRule = field(default_factory=SelectionRule)

    @property
    def model(self) -> str:
        """``'slip_jump'`` or ``'valve'``: the friction law of the best friction model."""
        return str(self.parameters["model"])

    @property
    def big(self) -> bool:
        """Whether the band reaches the one that matters."""
        return bool(self.band >= self.band_needed)

    @property
    def moves(self) -> bool:
        """Whether the fitted valve moves as a sticking one does (:func:`~.stiction.hammerstein.friction_moves`)."""
        return bool(friction_moves(self.slips, self.op_working_range))

    @property
    def present(self) -> bool:
        """The free-run verdict: friction pays, its band matters and the fitted valve slips."""
        return bool(self.significant and self.big and self.moves)

    def to_dict(self) -> dict:
        """The JSON keys of the free-run test (values as computed)."""
        return {"model": self.model, "parameters": dict(self.parameters), "units": dict(UNITS),
                "delta_ic": self.delta_ic, "significant": bool(self.significant), "band": self.band,
                "slips": self.slips, "band_needed": self.band_needed, "op_working_range": self.op_working_range,
                "n_eff": self.n_eff, "frictionless_model": self.frictionless_model,
                "frictionless_rmse": self.frictionless_rmse, "friction_rmse": self.friction_rmse,
                "compared": dict(self.compared)}


@dataclass(frozen=True)
class KStepTest:
    """The same friction test on k-step-ahead predictions (robust to slow unmeasured loads).

    Attributes
    ----------
    delta_ic : float, criterion change from the best frictionless to the best friction k-step fit
    horizon : int, samples between restarts of the measured level
    band : float, the best friction fit's band [fraction of stroke]
    slips : int, how often its valve moves over the record
    rmse : mapping ``frictionless``, ``friction`` -> RMSE [PV units]
    models : mapping ``frictionless``, ``friction`` -> model label
    """

    delta_ic: float
    horizon: int
    band: float
    slips: int
    rmse: Mapping[str, float]
    models: Mapping[str, str]

    def to_dict(self) -> dict:
        """The JSON keys of the k-step test (``kstep_*``)."""
        return {"kstep_delta_ic": self.delta_ic, "kstep_horizon": self.horizon, "kstep_band": self.band,
                "kstep_slips": self.slips, "kstep_rmse": dict(self.rmse), "kstep_models": dict(self.models)}


def model_based_readings(free_run: FreeRunTest, kstep: KStepTest | None) -> dict:
    """The model-based tests as the mapping the stiction evidence reads.

    Keys of the JSON: ``tested``, ``present`` and ``model_based_present`` (the free-run verdict), the
    free-run test's keys and the k-step test's ``kstep_*`` keys (read by
    :func:`~.stiction.hammerstein.hammerstein_evidence`, :func:`~.stiction.kstep.kstep_evidence` and
    :func:`~.stiction.combine.public_present`).
    """
    d = {"present": free_run.present, "tested": True, **free_run.to_dict()}
    if kstep is not None:
        d.update(kstep.to_dict())
    d["model_based_present"] = free_run.present
    return d


def frozen_position(stem: Evidence | None, free_run: FreeRunTest) -> FrozenPosition | None:
    """What a recorded position that never moved says, read with the process model.

    Where the recorded position stays put while the output travels (the stem test's ``frozen``), the
    friction fit of the process model says which: where the output's working range is at least
    :data:`~.stiction.hammerstein.SEIZED_TRAVEL` of the stroke, a valve that does not move needs a
    friction band of at least half that range (and the band that matters) to explain a process that
    does not follow the output, and is then ``'seized'``; a process that follows the output with a
    smaller band means the valve moves and the position signal is frozen (``'frozen_signal'``).
    Below that travel a frozen signal on a healthy valve with a quiet output fits a band of the
    output's size as well, and nothing is concluded (``'short_travel'``).  None where the position
    moved or was not recorded.
    """
    if stem is None or not stem.details.get("frozen"):
        return None
    band, travel = float(free_run.band), float(free_run.op_working_range)
    if travel >= SEIZED_TRAVEL and band >= 0.5 * travel and band >= float(free_run.band_needed):
        return "seized"
    if travel < SEIZED_TRAVEL:
        return "short_travel"
    return "frozen_signal"


@dataclass(frozen=True)
class FrictionVerdict(Mapping[str, Any]):
    """Does the valve stick?  The friction verdict of one diagnosis (``DiagnosisResult.stiction``).

    Built once by :func:`decide_friction` (or :meth:`untested` for a pump); numbers, flags and short codes
    only: :func:`~valve_gym.diagnosis.explain.explain_friction` writes it in words.

    Attributes
    ----------
    tested : bool, False where there is no valve (a pump)
    present : bool, the public verdict: the valve sticks
    free_run, kstep : FreeRunTest, KStepTest or None, the model-based friction tests
        (no k-step test with a measurement effect in the model)
    horch : mapping or None, Horch's model-free cross-correlation test (a second opinion, not in the verdict)
    combined : StictionAssessment or None, the stiction methods combined (probability, S and J with
        90 % intervals, each method's evidence)
    methods_present : bool, the verdict of the methods and the model-based tests
        (:func:`~valve_gym.diagnosis.stiction.combine.public_present`), before the stem and the cause
    verdict_source : {'methods', 'stem', 'stem+model'} or None
    frozen : {'seized', 'short_travel', 'frozen_signal'} or None, what a recorded position that never
        moved says (:func:`frozen_position`)
    overruled_by : OscillationCause or None, the cause of the oscillation that overrules a stiction
        verdict (another cause more probable, stiction below one half)
    naming_agrees : bool or None, whether naming the slip-jump effect and the verdict agree
        (None where no valve was tested)
    """

    tested: bool
    present: bool
    free_run: FreeRunTest | None = None
    kstep: KStepTest | None = None
    horch: Mapping[str, Any] | None = None
    combined: StictionAssessment | None = None
    methods_present: bool = False
    verdict_source: VerdictSource | None = None
    frozen: FrozenPosition | None = None
    overruled_by: OscillationCause | None = None
    naming_agrees: bool | None = None

    @staticmethod
    def untested() -> FrictionVerdict:
        """The verdict where there is no valve to stick (a pump)."""
        return FrictionVerdict(tested=False, present=False)

    # ------------------------------------------------------------------ derived readings
    @property
    def model_based_present(self) -> bool:
        """The free-run model-based verdict."""
        return bool(self.free_run is not None and self.free_run.present)

    @property
    def verdict(self) -> str | None:
        """The combined verdict: ``'stiction'``, ``'no stiction'`` or ``'undecided'``.

        The methods combined, ``'no stiction'`` where a cause of the oscillation overrules them (None
        without a combination).
        """
        if self.combined is None:
            return None
        return "no stiction" if self.overruled_by is not None else self.combined.verdict

    @property
    def probability(self) -> float:
        """Probability of stiction of the methods combined (nan without a combination)."""
        return math.nan if self.combined is None else float(self.combined.probability)

    @property
    def present_before_cause(self) -> bool:
        """The verdict before the cause of the oscillation was read."""
        return bool(self.present or self.overruled_by is not None)

    @property
    def kstep_decides(self) -> bool:
        """Whether the k-step test alone calls the valve sticky (the methods combined and the free run do not)."""
        return bool(self.methods_present and self.combined is not None and self.combined.verdict != "stiction"
                    and not self.model_based_present)

    def evidence_of(self, method: str) -> Evidence | None:
        """The combined assessment's evidence of ``method`` (``'stem'``, ``'kstep'``, ...), None if absent."""
        if self.combined is None:
            return None
        return next((e for e in self.combined.evidence if e.method == method), None)

    # ------------------------------------------------------------------ output
    def to_dict(self) -> dict:
        """JSON-ready dict: the keys of ``stiction`` in the diagnosis JSON (nan becomes None)."""
        return json_ready(self._view)

    @cached_property
    def _view(self) -> dict:
        """The JSON keys, values as computed (nan kept); the paragraph by :func:`.explain.explain_friction`."""
        from .explain import explain_friction

        if not self.tested or self.free_run is None:
            return {"present": bool(self.present), "tested": False, "reason": explain_friction(self),
                    "model": None, "parameters": {}, "naming_agrees": self.naming_agrees}
        d = {"present": bool(self.present), "tested": True, **self.free_run.to_dict(),
             "explanation": explain_friction(self)}
        if self.kstep is not None:
            d.update(self.kstep.to_dict())
        if self.horch is not None:
            d["horch"] = self.horch
        if self.combined is not None:
            a = self.combined.to_dict()
            d["model_based_present"] = self.model_based_present
            d["verdict_source"] = self.verdict_source
            for k in ("probability", "verdict", "S", "J", "S_interval", "J_interval", "sizes_agree", "sizes",
                      "evidence", "features", "contributions"):
                d[k] = a[k]
            d["verdict"] = self.verdict
            d["present_before_cause"] = self.present_before_cause
            if self.overruled_by is not None:
                d["verdict_before_cause"] = self.combined.verdict
        d["naming_agrees"] = self.naming_agrees
        return d

    # read-only mapping over the JSON keys
    def __getitem__(self, key: str) -> Any:
        return self._view[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._view)

    def __len__(self) -> int:
        return len(self._view)

    def __repr__(self) -> str:
        src = f", source={self.verdict_source!r}" if self.verdict_source else ""
        return (f"FrictionVerdict(tested={self.tested}, present={self.present}, verdict={self.verdict!r}, "
                f"probability={self.probability:.3g}{src})")


def decide_friction(free_run: FreeRunTest, kstep: KStepTest | None, assessment: StictionAssessment,
                    cause: OscillationCause | None, *, horch: Mapping[str, Any] | None = None,
                    named_slip_jump: bool = False) -> FrictionVerdict:
    """The friction verdict of a valve: every reading in, one :class:`FrictionVerdict` out.

    ``present`` is True when the methods combined say ``'stiction'``, or when the free-run
    model-based test finds friction that the k-step test does not contradict, or the k-step test
    finds a friction band that matters on its own
    (:func:`~valve_gym.diagnosis.stiction.combine.public_present`); ``'undecided'`` alone is False.
    Held out, this beats the model-based verdict alone (``docs/diagnosis.md``, section 4).  Where the
    record holds the valve's position and the stem test applies (:mod:`~.stiction.stem`), ``present``
    is the stem test's verdict instead (``verdict_source`` ``'stem'``); where the position never
    moved, :func:`frozen_position` tells a seized valve (``'stem+model'``, present) from a frozen
    signal.  Last, where the loop oscillates and another cause is more probable than stiction
    (``cause``, :func:`~.causes.oscillation_cause`), with the stiction probability below one half,
    the verdict is no stiction (``overruled_by``), unless the stem was read: an oscillation alone is
    no evidence against the valve when the tuning, a disturbance or the sensor explains it.

    Parameters
    ----------
    free_run, kstep : the model-based tests (``kstep`` None where it did not run)
    assessment : StictionAssessment of the record (:func:`~.stiction.assess_stiction`, given
        :func:`model_based_readings` of the two tests)
    cause : OscillationCause or None, why the loop oscillates
    horch : mapping, optional, Horch's test (kept as a second opinion)
    named_slip_jump : bool, whether the slip-jump effect was named by the effect selection
    """
    methods_present = public_present(assessment.verdict, model_based_readings(free_run, kstep))
    present, source = methods_present, "methods"
    stem = next((e for e in assessment.evidence if e.method == "stem"), None)
    if stem is not None and stem.applicable:
        # the valve's position is recorded: whether the stem follows the output is read, not inferred
        present, source = stem.verdict == "stiction", "stem"
    frozen = frozen_position(stem, free_run)
    if frozen == "seized":
        present, source = True, "stem+model"
    overruled = (cause is not None and cause.oscillating and present and cause.cause != "stiction"
                 and cause.p_stiction < 0.5 and source != "stem")
    if overruled:
        present = False
    return FrictionVerdict(tested=True, present=bool(present), free_run=free_run, kstep=kstep, horch=horch,
                           combined=assessment, methods_present=bool(methods_present), verdict_source=source,
                           frozen=frozen, overruled_by=cause if overruled else None,
                           naming_agrees=(not named_slip_jump) or bool(present))
