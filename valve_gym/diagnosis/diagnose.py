"""The diagnosis: fit, locate the mismatch, name the missing physics, judge the valve.

:func:`diagnose` runs the whole chain on one recording and returns a
:class:`DiagnosisResult`; :func:`diagnose_many` runs it on many recordings in
parallel worker processes.  Plots and the markdown report are separate
(:mod:`valve_gym.diagnosis.report`).
"""
from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from ..effects import candidate_effects, effect_spec
from .causes import OscillationCause, oscillation_cause
from .explain import explain_effect, explain_naming_conflict, explain_none
from .fit import (
    AUTO_THOROUGH_SAMPLES,
    FitResult,
    fit_initial_state,
    fit_structure,
    fit_with_friction,
    resolve_effort,
    rmse,
    search_cost,
    transfer,
)
from .indices import horch_ccf
from .locate import MismatchReport, condition_masks, locate_mismatch
from .model import (
    ACTUATORS,
    PLANTS,
    POSITIVE_GAIN_PLANTS,
    DataScales,
    ModelStructure,
    pool_map,
    process_gain_sign,
    process_pool,
)
from .pairing import controller_reaction
from .plant_choice import resolve_plant
from .recording import Recording, RecordingError
from .select import Selection, SelectionRule, friction_band, op_working_range, select_effects
from .stiction import StictionAssessment, assess_stiction
from .verdict import FreeRunTest, FrictionVerdict, KStepTest, decide_friction, json_ready, model_based_readings
from .verdict import finite_or_none as _f

__all__ = ["DiagnosisResult", "diagnose", "diagnose_many", "validate_on", "simulate_same_state",
           "JSON_SCHEMA_KEYS", "AUTO_THOROUGH_SAMPLES", "coarse_factor"]

#: Top-level keys every diagnosis JSON has.
JSON_SCHEMA_KEYS = ("recording", "settings", "effects", "base", "final", "holdout", "mismatch",
                    "mismatch_conditions", "residual_tests", "candidates", "skipped",
                    "explanation", "stiction", "cause", "validation", "timing")


@dataclass(frozen=True)
class DiagnosisResult:
    """Everything a diagnosis found (compute only; plotting is in :mod:`.report`).

    Built once by :func:`diagnose` and frozen (its fields are not reassigned).

    Attributes
    ----------
    recording : Recording
    plant, actuator : str
    effects : list of str, effects added (empty: the base model is enough)
    base, final : FitResult, base and selected model fitted on the whole record
    base_split, final_split : FitResult, the same fitted on the fit part only
        (their ``holdout_rmse`` is the error on the held-out end)
    selection : Selection, every candidate tried
    mismatch : MismatchReport of the base model (whole record)
    mismatch_final : MismatchReport of the selected model
    explanation : list of str, one paragraph per added effect (or why none)
    stiction : FrictionVerdict, the friction verdict (``to_dict()``: the JSON's ``stiction``)
    cause : OscillationCause, the probabilities of the causes of an oscillation, with their evidence
    validation : dict or None, results on another recording
    timing : dict, seconds per stage
    settings : dict
    """

    recording: Recording
    plant: str
    actuator: str
    effects: list[str]
    base: FitResult
    final: FitResult
    base_split: FitResult
    final_split: FitResult
    selection: Selection
    mismatch: MismatchReport
    mismatch_final: MismatchReport
    explanation: list[str]
    stiction: FrictionVerdict
    validation: dict | None
    timing: dict
    settings: dict
    frictionless: FitResult | None = None
    #: Why the loop oscillates (:func:`~valve_gym.diagnosis.causes.oscillation_cause`), built once
    cause: OscillationCause | None = None
    #: Simulated PV of the base and final models on the validation recording, and that recording
    _validation_series: tuple[np.ndarray, np.ndarray, Recording] | None = field(default=None, repr=False)

    # ------------------------------------------------------------------ output
    def to_dict(self) -> dict:
        """JSON-ready dict; top-level keys :data:`JSON_SCHEMA_KEYS`."""
        rec = self.recording
        n_fit = self.base_split.n_fit
        hold = {"fraction": _f(1 - n_fit / len(rec)), "n_fit": int(n_fit),
                "t_split": _f(rec.t[n_fit]) if n_fit < len(rec) else None,
                "base_rmse": _f(self.base_split.holdout_rmse),
                "final_rmse": _f(self.final_split.holdout_rmse),
                "base_fit_percent": _f(self.base_split.holdout_fit_percent),
                "final_fit_percent": _f(self.final_split.holdout_fit_percent),
                "n_eff": _f(self.selection.n_eff)}
        d = {
            "recording": {"name": rec.name, "n": len(rec), "dt": rec.dt,
                          "duration": rec.duration, "op_range": list(rec.op_range),
                          "columns": dict(rec.columns), "repairs": list(rec.repairs),
                          "notes": list(rec.notes), "start": rec.start},
            "settings": self.settings,
            "effects": list(self.effects),
            "base": self.base.summary(),
            "final": self.final.summary(),
            "holdout": hold,
            "mismatch": [_region(r) for r in self.mismatch.regions],
            "mismatch_conditions": [c.__dict__ for c in self.mismatch.conditions],
            "residual_tests": {"base": _tests(self.mismatch), "final": _tests(self.mismatch_final)},
            "candidates": [c.summary() for c in self.selection.candidates],
            "skipped": dict(self.selection.skipped),
            "explanation": list(self.explanation),
            "stiction": self.stiction.to_dict(),
            "cause": self.cause.to_dict() if self.cause is not None else None,
            "validation": self.validation,
            "timing": self.timing,
        }
        return json_ready(d)

    def to_json(self, indent: int = 2) -> str:
        """The result as a JSON string (see :meth:`to_dict`)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    def summary_row(self) -> dict:
        """One row for a summary table of many recordings."""
        h = self.to_dict()["holdout"]
        return {"recording": self.recording.name, "plant": self.plant, "actuator": self.actuator,
                "n": len(self.recording), "effects": ",".join(self.effects) or "none",
                "base_rmse": self.base.rmse_all, "final_rmse": self.final.rmse_all,
                "base_fit_percent": self.base.fit_percent_all,
                "final_fit_percent": self.final.fit_percent_all,
                "holdout_base_rmse": h["base_rmse"], "holdout_final_rmse": h["final_rmse"],
                "stiction": self.stiction.present,
                "cause": self.cause.cause if self.cause is not None else None,
                "regions": len(self.mismatch.regions),
                "seconds": self.timing.get("total")}

    def __repr__(self):
        return (f"DiagnosisResult({self.recording.name!r}, plant={self.plant!r}, "
                f"effects={self.effects}, rmse {self.base.rmse_all:.4g} -> "
                f"{self.final.rmse_all:.4g}, stiction={self.stiction.present})")


def _region(r):
    d = dict(r.__dict__)
    return d


def _tests(mm: MismatchReport) -> dict:
    t = mm.tests
    return {"rms": mm.rms, "noise_std": t.noise_std, "ljung_box_q": t.ljung_box_q,
            "ljung_box_p": t.ljung_box_p, "white": t.white, "acf_bound": t.acf_bound,
            "acf_outside": t.acf_outside, "acf": t.acf, "ccf_bound": t.ccf_bound,
            "ccf_outside": t.ccf_outside, "ccf_peak_lag": t.ccf_peak_lag, "ccf_peak": t.ccf_peak,
            "ccf_lags": t.ccf_lags, "ccf": t.ccf, "period": t.period, "n_eff": t.n_eff,
            "threshold": mm.threshold, "window": mm.window}


# search budgets of the stages per ``effort``
_EFFORT_PLAN = {
    "fast": {"base": "normal", "screen": "fast", "confirm": "normal", "n_confirm": 2,
             "verdict": "fast"},
    "normal": {"base": "thorough", "screen": "fast", "confirm": "thorough", "n_confirm": 2,
               "verdict": "normal"},
    "thorough": {"base": "thorough", "screen": "normal", "confirm": "thorough", "n_confirm": 4,
                 "verdict": "thorough"},
}


# --------------------------------------------------------------------------- helpers
def _refit_full(split: FitResult, rec: Recording, seed: int, effort: str, fast: bool = False) -> FitResult:
    """Refit a split fit on the whole record (same structure and scales), warm-started."""
    if split.n_fit >= len(rec):
        return split
    seeds = split.w[None, :]
    spread = np.full(split.k, 0.05) if fast else None
    return fit_structure(split.structure, rec.op, rec.pv, None, seeds=seeds, spread=spread, rng=seed,
                         effort=effort, early_stop=fast)


def _locate(rec: Recording, res: FitResult) -> MismatchReport:
    sc = res.structure.scales
    return locate_mismatch(rec.t, rec.op, rec.pv, res.y_sim, sp=rec.sp, dt=rec.dt,
                           sat_hi=sc.sat_hi, sat_lo=sc.sat_lo)


def validate_on(fitted: Sequence[FitResult], other: Recording, seed: int = 0) -> list[FitResult]:
    """Simulate fitted models on another recording's input, initial state refitted.

    Returns one :class:`FitResult` per model, on ``other`` (``rmse_all`` is
    the validation RMSE).
    """
    return [fit_initial_state(f, other.op, other.pv, rng=seed) for f in fitted]


def simulate_same_state(fit: FitResult, other: Recording) -> np.ndarray:
    """Free-run PV of a fitted model on another recording's input, from the fitted initial state.

    For a second record known to start where the fitted one started (the
    cascaded-tanks benchmark's test record does): nothing is refitted.
    """
    return fit.structure.simulate(fit.w[None, :], other.op, n_sub=fit.n_sub)[:, 0]


def _friction_params(fit: FitResult) -> dict:
    p = fit.physical
    if "slip_jump.S" in p:
        return {"model": "slip_jump", "S": p["slip_jump.S"], "J": p["slip_jump.J"],
                "band": p["slip_jump.S"]}
    return {"model": "valve", "z_max": p.get("valve.z_max"), "e_dead": p.get("valve.e_dead"),
            "dead_band": 2 * p.get("valve.e_dead", 0.0), "band": 2 * p.get("valve.e_dead", 0.0)}


def _fit_task(args):
    st, u, y, seeds, spread, seed, effort, coarse, horizon = args
    return fit_structure(st, u, y, None, seeds=seeds, spread=spread, rng=seed, effort=effort, coarse=coarse,
                         early_stop=spread is not None, horizon=horizon)


#: Samples of the k-step-ahead prediction of the load-robust friction test (the measured level restarts
#: from the record every this many samples; at most a quarter of the record).
KSTEP_HORIZON = 60


def kstep_horizon(n_samples: int) -> int:
    """Horizon of the k-step friction test for a record of ``n_samples``: :data:`KSTEP_HORIZON`, at most n/4."""
    return int(max(2, min(KSTEP_HORIZON, n_samples // 4)))


def _kstep_tasks(tasks: list[tuple[ModelStructure, np.ndarray]], n_frictionless: int) -> list[int]:
    """Which verdict fits are repeated as k-step predictions (indices into ``tasks``).

    The frictionless valve, with a dead time if that is an alternative, then the two friction
    forms (the paper's valve and the slip-jump valve); none when a measurement effect is in the model.
    """
    st0 = tasks[0][0]
    if not st0.pv_is_simulated_level:
        return []
    pick = [0] + [i for i in range(1, n_frictionless) if "dead_time" in tasks[i][0].effects
                  and "dead_time" not in st0.effects]
    return pick + list(range(n_frictionless, len(tasks)))


#: Records of at least this many samples are searched coarse-to-fine.
COARSE_FROM_SAMPLES = 2400


def coarse_factor(n_samples: int) -> int:
    """Decimation of the coarse-to-fine search for a record of ``n_samples`` (1 = off).

    ``n // 1200`` from :data:`COARSE_FROM_SAMPLES` samples on (3 for 3600
    samples): the evolution then runs on about 1200 samples, the
    warm-started refinement on all of them.  Shorter records are searched on
    every sample, as before.
    """
    return max(1, n_samples // 1200) if n_samples >= COARSE_FROM_SAMPLES else 1


class _FrictionTests(NamedTuple):
    """The model-based friction tests of :func:`_friction_tests` (all None for a pump)."""

    free_run: FreeRunTest | None    # friction against frictionless models, free-run, whole record
    kstep: KStepTest | None         # the same on k-step-ahead predictions (None where it did not run)
    frictionless: FitResult | None  # the best frictionless model of the free-run test
    final: FitResult                # the final model, or the test's nested optimum of it where that is better
    slip: FitResult | None          # the slip-jump friction fit (for S and J with intervals)


def _friction_tests(final: FitResult, rec: Recording, mm: MismatchReport, cfg: _Config,
                    executor=None) -> _FrictionTests:
    """Does the valve stick?  Friction models against frictionless ones, whole record.

    Friction (the paper's valve and the slip-jump valve, each with the final
    model's other effects) is compared by the information criterion with the
    best *frictionless* alternative: the final model with a frictionless valve,
    and the same with a dead time or a sensor lag added (a sticky valve delays
    the response, so friction must beat the other ways of delaying it).  The
    valve sticks when the best friction model lowers the criterion by more
    than ``rule.ic_margin`` and its band (dead band ``2 e_dead`` or slip-jump
    ``S``) is at least ``rule.min_band`` of the stroke and either
    ``rule.abs_band`` of the stroke or ``rule.rel_band`` of the controller
    output's working range (2-98 % percentiles).  The
    held-out test of the effect selection is not used here: a two-hour plant
    record often holds one or two stick-slip episodes, and a held-out end
    without one can neither confirm nor refute friction.
    """
    st = final.structure
    if st.actuator != "valve":
        return _FrictionTests(None, None, None, final, None)
    rule, seed, effort, coarse, fast = cfg.rule, cfg.seed, cfg.plan["verdict"], cfg.q, cfg.fast
    u, y = rec.op, rec.pv
    base_eff = tuple(e for e in st.effects if e != "slip_jump")
    tasks, n_frictionless = _verdict_tasks(final, base_eff)
    args = [(t[0], u, y, t[1], transfer(final, t[0])[1] if fast else None, seed + 17 + i, effort, coarse, None)
            for i, t in enumerate(tasks)]
    ks = _kstep_tasks(tasks, n_frictionless)
    horizon = kstep_horizon(len(y))
    args += [(tasks[i][0], u, y, tasks[i][1], None, seed + 41 + i, "fast", 1, horizon) for i in ks]
    fits = pool_map(executor, _fit_task, args, [search_cost(a[0], len(y), a[6], a[7]) for a in args])
    fits, kfits = fits[:len(tasks)], fits[len(tasks):]
    frictionless, fric = fits[:n_frictionless], fits[n_frictionless:]
    _nest_on_frictionless(fric, frictionless[0], u, y)
    n = len(y)
    from .fit import effective_n, information_criterion
    best0 = min(frictionless, key=lambda f: information_criterion(
        f.cost, effective_n(f.residual), f.k, n, rule.criterion))
    n_eff = effective_n(best0.residual)

    def ic(f: FitResult) -> float:
        return information_criterion(f.cost, n_eff, f.k, n, rule.criterion)

    best1 = min(fric, key=ic)
    free_run = _free_run_test(best0, best1, frictionless + fric, u, d_ic=ic(best1) - ic(best0), n_eff=n_eff,
                              rule=rule, mm=mm, lag_alt=tuple(e for e in best0.structure.effects if e not in base_eff))
    kstep = None
    if kfits:
        n_kf = len(ks) - (len(tasks) - n_frictionless)
        kstep = _kstep_test(kfits[:n_kf], kfits[n_kf:], u, rule=rule, horizon=horizon)
    # keep the nested optimum as the final model when it is the same structure and better
    new_final = final
    for f in fric:
        if f.structure.effects == st.effects and f.cost < final.cost:
            new_final = f
    slip = next((f for f in fric if "slip_jump" in f.structure.effects), None)
    return _FrictionTests(free_run, kstep, best0, new_final, slip)


def _kstep_test(frictionless: list[FitResult], friction: list[FitResult], u: np.ndarray, *,
                rule: SelectionRule, horizon: int) -> KStepTest:
    """The friction test on k-step-ahead predictions: criterion change from the best frictionless fit.

    Each list holds fits on k-step predictions (``frictionless``: the frictionless valve, and with a
    dead time; ``friction``: the paper's valve and the slip-jump valve).  The free-run test compares
    models that must also reproduce every slow unmeasured load from the controller output alone;
    there the load's error often outweighs what friction explains (a severe valve under a drifting
    load: equal free-run errors with and without friction).  Restarting the
    measured level from the record every ``horizon`` samples leaves the valve's stick-slip in the
    error and takes most of the load out.
    """
    from .fit import effective_n, information_criterion

    n = len(friction[0].y)
    n_eff = effective_n(min(frictionless, key=lambda f: f.cost).residual)

    def ic(f: FitResult) -> float:
        return information_criterion(f.cost, n_eff, f.k, n, rule.criterion)

    best0, best1 = min(frictionless, key=ic), min(friction, key=ic)
    return KStepTest(delta_ic=float(ic(best1) - ic(best0)), horizon=int(horizon), band=friction_band(best1),
                     slips=valve_slips(best1, u),
                     rmse={"frictionless": float(best0.rmse_all), "friction": float(best1.rmse_all)},
                     models={"frictionless": best0.label, "friction": best1.label})


def _verdict_tasks(final: FitResult,
                   base_eff: tuple[str, ...]) -> tuple[list[tuple[ModelStructure, np.ndarray]], int]:
    """Fits of the friction verdict, all seeded from the final model, and how many are frictionless.

    Returns ``(structure, seeds (m, k))`` pairs: the frictionless alternatives
    first (the final model's effects with a frictionless valve, then with a
    dead time or a sensor lag added), then the two friction forms (the
    paper's valve and the slip-jump valve).
    """
    st = final.structure
    st0 = st.with_effects(base_eff, friction=False)
    tasks = []          # (structure, seeds): all seeded from the final model, independent
    seeds0, _ = transfer(final, st0)
    tasks.append((st0, seeds0))
    for lag in (e for e in candidate_effects() if effect_spec(e).rivals_friction):
        if lag in base_eff:
            continue
        stl = st0.with_effects(base_eff + (lag,))
        tasks.append((stl, transfer(final, stl)[0]))
    n_frictionless = len(tasks)
    for form in ("valve", "slip_jump"):
        eff = base_eff + (("slip_jump",) if form == "slip_jump" else ())
        stf = st.with_effects(eff, friction=True)
        sf, _ = transfer(final, stf)
        sz = sf.copy()                  # the same with friction at zero: nested on frictionless
        for name in ("e_dead", "z_max", "S"):
            if name in stf.names:
                sz[0, stf.index(name)] = 0.0
        sf = np.vstack([sz, sf] + ([final.w[None, :]] if stf.effects == st.effects else []))
        tasks.append((stf, sf))
    return tasks, n_frictionless


def _nest_on_frictionless(fric: list[FitResult], fr0: FitResult, u: np.ndarray, y: np.ndarray) -> None:
    """Replace, in place, a friction fit worse than the frictionless one by the nested optimum."""
    for i, f in enumerate(fric):
        if f.cost > fr0.cost:
            # nested: friction at zero reproduces the frictionless optimum exactly
            w, _ = transfer(fr0, f.structure)
            for name in ("e_dead", "z_max", "S"):
                if name in f.structure.names:
                    w[0, f.structure.index(name)] = 0.0
            fric[i] = fit_structure(f.structure, u, y, None, seeds=w, w_fixed=w[0], free=[])


#: Stem movement per sample (fraction of stroke) that counts as the fitted valve moving.
SLIP_STEP = 1e-4


def valve_slips(fit: FitResult, u: np.ndarray) -> int:
    """How often the fitted valve of ``fit`` moves over the output ``u``: runs of moving samples.

    The stem is simulated from the output alone (the friction block's own state), so the count
    is the same for a free-run and a k-step fit of the same parameters.
    """
    h = fit.structure.stem(fit.w, np.asarray(u, float), n_sub=fit.n_sub)
    moving = np.abs(np.diff(h)) > SLIP_STEP
    return int(np.count_nonzero(moving[1:] & ~moving[:-1]) + (1 if moving.size and moving[0] else 0))


def _free_run_test(best0: FitResult, best1: FitResult, compared: list[FitResult], u: np.ndarray, *,
                   d_ic: float, n_eff: float, rule: SelectionRule, mm: MismatchReport,
                   lag_alt: tuple[str, ...]) -> FreeRunTest:
    """The free-run friction test of the best frictionless (``best0``) and friction (``best1``) fits.

    ``d_ic`` is the change of the information criterion from ``best0`` to
    ``best1``; ``compared`` are all the fits of the test.
    """
    return FreeRunTest(parameters=_friction_params(best1), delta_ic=d_ic, significant=bool(d_ic < -rule.ic_margin),
                       band=friction_band(best1), slips=valve_slips(best1, u), band_needed=rule.band_needed(u),
                       op_working_range=op_working_range(u), n_eff=n_eff, frictionless_model=best0.label,
                       frictionless_rmse=best0.rmse_all, friction_rmse=best1.rmse_all,
                       compared={f.label: f.rmse_all for f in compared}, lag_alt=lag_alt,
                       reversal=mm.condition("near_op_reversal"), rule=rule)


def _assess(rec: Recording, logged: Recording, plant: str, tests: _FrictionTests,
            executor=None) -> StictionAssessment:
    """The combined assessment of the stiction methods (:func:`~.stiction.assess_stiction`).

    The data-driven methods read ``logged`` (the record as logged), the S profile of the slip-jump fit
    reads ``rec`` (the record as paired for the model); the model-based evidence reads the two
    friction tests (:func:`~.verdict.model_based_readings`), the stem test the recorded position.
    """
    assert tests.free_run is not None
    return assess_stiction(logged.op, logged.pv, float(logged.dt or 1.0), plant, sp=logged.sp,
                           verdict=model_based_readings(tests.free_run, tests.kstep), slip_fit=tests.slip,
                           map_fn=None if executor is None else executor.map,
                           fit_data=None if logged is rec else (rec.op, rec.pv), mv=logged.mv)


#: Searches :func:`diagnose` knows (``search=``).
SEARCHES = ("fast", "full")


def _resolve_search(search: str) -> bool:
    """Whether ``search`` asks for the fast search (warm-start clouds and early stops)."""
    if search not in SEARCHES:
        raise ValueError(f"search must be one of {', '.join(SEARCHES)}, got {search!r}")
    return search == "fast"


def _resolve_coarse(coarse, n_samples: int) -> int:
    """The decimation factor ``coarse`` stands for (see :func:`coarse_factor`)."""
    if coarse == "auto":
        return coarse_factor(n_samples)
    if isinstance(coarse, (int, np.integer)) and not isinstance(coarse, bool) and coarse >= 1:
        return int(coarse)
    raise ValueError(f"coarse must be 'auto' or a whole number >= 1, got {coarse!r}")


def _validate_other(base: FitResult, final: FitResult, validate: Recording, seed: int) -> dict:
    """Base and final model on another recording: initial state refitted and kept."""
    vb, vf = validate_on([base, final], validate, seed=seed)
    same = [rmse(validate.pv, simulate_same_state(f, validate)) for f in (base, final)]
    return {"recording": validate.name, "n": len(validate),
            "initial_state": "refitted on this recording (the *_same_state RMSEs keep "
                             "the fitted recording's initial state)",
            "base_rmse": vb.rmse_all, "final_rmse": vf.rmse_all,
            "base_rmse_same_state": same[0], "final_rmse_same_state": same[1],
            "base_fit_percent": vb.fit_percent_all,
            "final_fit_percent": vf.fit_percent_all,
            "base_initial_state": {k: v for k, v in vb.physical.items() if k.startswith("init.")},
            "final_initial_state": {k: v for k, v in vf.physical.items() if k.startswith("init.")},
            "_y_base": vb.y_sim, "_y_final": vf.y_sim}


# --------------------------------------------------------------------------- main API
def diagnose(recording: Recording, plant: str = "auto", actuator: str = "valve", *,
             candidates: Sequence[str] | str | None = None, holdout: float = 0.3,
             validate: Recording | None = None, rule: SelectionRule = SelectionRule(),
             effort: str = "auto", seed: int = 0, jobs: int = 1, saturation="auto",
             n_sub: int = 1, coarse: int | str = 1, search: str = "full", op_lag: int | str = "auto",
             progress: Callable[[str], None] | None = None) -> DiagnosisResult:
    """Diagnose one recording: base fit, mismatch location, missing physics, friction verdict.

    Parameters
    ----------
    recording : Recording
        From :func:`~valve_gym.diagnosis.recording.load_recording`.
    plant : {'auto', 'tank', 'integrating', 'first_order', 'cascade'}
        ``'auto'`` (default): from the ISA tag of the PV column, else of the recording's name
        (:func:`~valve_gym.diagnosis.plant_choice.plant_from_name`: ``LIC...``/``LT`` integrating,
        ``FIC``/``PIC``/``TIC``/``AIC...`` first order), else from the data
        (:func:`~valve_gym.diagnosis.plant_choice.plant_from_data`: self-regulating or integrating,
        with or without dead time, fitted and compared); the choice and its reason are in
        ``settings['plant_choice']``.
    actuator : {'valve', 'pump'}
    candidates : sequence of str, or str, optional
        Candidate effects (default all of
        :data:`~valve_gym.diagnosis.model.CANDIDATE_EFFECTS` that apply);
        an empty sequence only fits the base model. A string names one
        effect, or several separated by commas (``'leak,overflow'``).
    holdout : float
        Fraction at the end of the record left out of the selection fits
        (0 disables the held-out test; the information criterion decides
        alone).
    validate : Recording, optional
        Another recording of the same loop: the base and final models
        (fitted on ``recording``) are simulated on its input with their
        initial state refitted.
    rule : SelectionRule
    effort : {'auto', 'fast', 'normal', 'thorough'}
        Search budget; ``'auto'`` (default) is ``'thorough'`` for records of up to
        :data:`AUTO_THOROUGH_SAMPLES` samples and ``'normal'`` for longer ones.
    seed : int
    jobs : int
        Worker processes for the candidate fits (1 = in this process).
    saturation : 'auto', None or (lo, hi)
        Sensor range of the PV.
    n_sub : int
        Euler steps per controller sample during the search (1: fastest; the
        fitted time constants then carry the explicit-Euler bias of about half
        a sample, 2 halves it at twice the cost).  The reported simulations use
        the smallest ``n_sub`` at least this large that passes
        :func:`valve_gym.core.check_dt`.
    coarse : 'auto' or int
        Decimation of the coarse-to-fine search (:func:`coarse_factor`:
        ``'auto'`` is 3 for 3600 samples, 1 below 2400).  Default 1: every
        fit searches every sample.  Coarse-to-fine is opt-in: on two
        3600-sample test records it named the same effects and verdicts with
        about 1.2x less CPU time (``benchmarks/bench_diagnosis.py --coarse auto
        --old``), too little evidence and too little gain to make it the default.
    search : {'full', 'fast'}
        ``'full'`` (default): every evolution starts from a Latin hypercube
        plus its seeds and spends its whole budget.  ``'fast'`` (opt-in): the
        confirmation fits, the whole-record refits and the friction verdict
        draw half of their first population around the warm start and end
        after ``max(20, generations / 4)`` generations without a gain
        (:func:`~valve_gym.diagnosis.fit.fit_structure`, ``early_stop``); the
        screening fits and every fit of a friction law the warm start does not
        know keep the whole search.  On four 3600-sample records it used 1.44x
        less CPU than revision e8f7925 (``'full'``: 1.23x;
        ``benchmarks/bench_diagnosis.py --before e8f7925 [--search fast]``) and
        named the same effects, but its final fits were up to 18 % worse in
        RMSE and it adds a second, spurious effect more often
        (``benchmarks/concealed_suite.py --search fast``).
    op_lag : 'auto', 0 or 1
        How the recorder pairs the controller output with the PV.  0: ``pv[k]``
        was measured after ``op[k]`` had acted for one sample (the model's
        convention).  1: ``op[k]`` was computed from the ``pv[k]`` logged beside
        it and acts only after it (a controller's scan logged as it happened);
        the diagnosis then pairs ``op[k-1]`` with ``pv[k]``
        (:meth:`Recording.with_op_lag`; one sample shorter).  ``'auto'``
        (default) reads it from the controller's reaction to PV moves
        (:func:`~valve_gym.diagnosis.pairing.controller_reaction`); when that is
        unclear it fits the base model both ways and takes 1 only when it lowers
        the information criterion by more than ``rule.ic_margin``; the test is
        in ``settings['op_lag_test']``.  The two are the same as a dead time of
        zero or one sample before the valve, so a longer dead time is still
        found as the ``dead_time`` effect, one sample shorter when 1 is chosen.
    progress : callable(str), optional

    Returns
    -------
    DiagnosisResult

    Examples
    --------
    >>> from valve_gym.diagnosis.synthetic import make_recording
    >>> rec = make_recording("overflow", seed=32, n=600)
    >>> res = diagnose(rec, plant="tank", candidates=("overflow", "leak"), effort="fast")
    >>> res.effects
    ['overflow']
    >>> round(res.final.physical["overflow.L_max_pv"], 2)   # the top of the tank [m] (true 1.35)
    1.35
    """
    t_all = time.perf_counter()
    plant, plant_choice, cands = _check_arguments(recording, plant, actuator, holdout, candidates)
    _check_seed_and_range(seed, saturation)
    lags = _resolve_op_lag(op_lag)
    if not isinstance(n_sub, (int, np.integer)) or n_sub < 1:
        raise ValueError(f"n_sub must be a positive whole number, got {n_sub!r}")
    say = progress or (lambda s: None)
    effort_asked, effort = effort, resolve_effort(effort, len(recording))
    cfg = _Config(plant=plant, actuator=actuator, holdout=holdout, saturation=saturation, n_sub=int(n_sub),
                  seed=seed, effort=effort, q=_resolve_coarse(coarse, len(recording)), fast=_resolve_search(search),
                  rule=rule, op_lag=op_lag, candidates=cands, jobs=jobs)
    ex = process_pool(jobs) if jobs > 1 else None      # one pool for every stage
    try:
        stages = _fit_stages(recording, lags, cfg, ex, say)
    finally:
        if ex is not None:
            ex.shutdown()
    rec, base_split, sel, fv, lag, align, timing = stages
    st, sc = base_split.structure, base_split.structure.scales
    base, final, mm = fv.base, fv.final, fv.mismatch
    if validate is not None:
        validate = validate.with_op_lag(lag)
    cause = None
    if fv.assessment is None or fv.tests.free_run is None:
        stiction = FrictionVerdict.untested()
    else:
        cause = _cause(rec, recording, plant, base, final, fv.assessment)
        stiction = decide_friction(fv.tests.free_run, fv.tests.kstep, fv.assessment, cause, horch=fv.horch,
                                   named_slip_jump="slip_jump" in sel.effects)
    expl = _explanations(rec, sel, base, final, mm)
    if "slip_jump" in sel.effects:
        expl[list(sel.effects).index("slip_jump")] += explain_naming_conflict(stiction)
    _note_poor_fit(expl, final, plant)
    # ---- validation
    validation, series = None, None
    if validate is not None:
        t0 = time.perf_counter()
        say(f"{rec.name}: validating on {validate.name}")
        validation = _validate_other(base, final, validate, seed)
        series = (validation.pop("_y_base"), validation.pop("_y_final"), validate)
        timing["validation"] = time.perf_counter() - t0
    timing["total"] = time.perf_counter() - t_all
    settings = {"plant": plant, "plant_choice": plant_choice, "actuator": actuator, "candidates": list(cands),
                "holdout": float(holdout), "effort": effort, "effort_asked": effort_asked,
                "seed": seed, "coarse_to_fine": cfg.q, "search": search, "op_lag": lag, "op_lag_test": align,
                "rule": dict(rule.__dict__), "n_sub_search": st.n_sub,
                "sensor_range": {"lo": sc.sat_lo, "hi": sc.sat_hi},
                "valve_model": ("quasi-static: tau = dt/n_sub, v_max = inf"
                                if actuator == "valve" else None)}
    return DiagnosisResult(recording=rec, plant=plant, actuator=actuator, effects=list(sel.effects),
                           base=base, final=final, base_split=base_split, final_split=sel.final,
                           selection=sel, mismatch=mm, mismatch_final=fv.mismatch_final, explanation=expl,
                           stiction=stiction, validation=validation, timing=timing, settings=settings,
                           frictionless=fv.tests.frictionless, cause=cause, _validation_series=series)


def _refit_task(args):
    return _refit_full(*args)


def _cause(rec: Recording, logged: Recording, plant: str, base: FitResult, final: FitResult,
           assessment: StictionAssessment) -> OscillationCause:
    """The cause of the loop's oscillation (:func:`~.causes.oscillation_cause`), given the stiction methods combined.

    The friction verdict follows it (:func:`~.verdict.decide_friction`): where the loop oscillates and
    another cause is more probable than stiction, with the stiction probability below one half, the
    verdict is no stiction.
    """
    physical = dict(base.physical)
    if "dead_time.theta" in final.physical:
        physical["dead_time.theta"] = final.physical["dead_time.theta"]
    said = tuple(rec.notes) + tuple(rec.repairs)
    span_known = not any("OP span unknown" in s for s in said)
    return oscillation_cause(logged.op, logged.pv, float(logged.dt or 1.0), sp=logged.sp, plant=plant,
                             p_stiction=float(assessment.probability), physical=physical,
                             y_model=final.y_sim if len(final.y_sim) == len(logged) else None,
                             evidence=assessment.evidence,
                             op_span=float(rec.op_range[1] - rec.op_range[0]), span_known=span_known)


@dataclass(frozen=True)
class _Config:
    """What :func:`diagnose` was asked, checked and resolved (the stages' settings)."""

    plant: str
    actuator: str
    holdout: float
    saturation: Any
    n_sub: int
    seed: int
    effort: str                 # resolved: 'fast', 'normal' or 'thorough'
    q: int                      # decimation of the coarse-to-fine search (1: off)
    fast: bool                  # the fast search (warm-start clouds, early stops)
    rule: SelectionRule
    op_lag: int | str           # as asked ('auto', 0 or 1)
    candidates: tuple[str, ...]
    jobs: int

    @property
    def plan(self) -> dict:
        """Search budgets of the stages (:data:`_EFFORT_PLAN`)."""
        return _EFFORT_PLAN[self.effort]


class _Stages(NamedTuple):
    """Outcome of :func:`_fit_stages`."""

    rec: Recording              # the record as paired for the model
    base_split: FitResult       # base model, fit part
    selection: Selection
    friction: _FrictionStage
    op_lag: int
    op_lag_test: dict
    timing: dict                # seconds per stage


def _fit_stages(recording: Recording, lags: tuple[int, ...], cfg: _Config, ex,
                say: Callable[[str], None]) -> _Stages:
    """Base fit, selection, whole-record refits and friction tests, on the process pool ``ex`` (or none)."""
    plant, seed, plan, q, fast, rule = cfg.plant, cfg.seed, cfg.plan, cfg.q, cfg.fast, cfg.rule
    timing: dict = {}
    t0 = time.perf_counter()       # ---- base fit on the fit part (on each OP/PV pairing asked for)
    reaction = None
    if len(lags) > 1 and plant in POSITIVE_GAIN_PLANTS:
        # the process gain's sign is the plant's: read the pairing before fitting, fit only that one
        reaction = controller_reaction(recording.op, recording.pv, 1.0)
        if reaction["op_lag"] is not None:
            lags = (reaction["op_lag"],)
    bases = _base_fits(recording, lags, cfg, ex, say)
    lag, align = _choose_op_lag(bases, rule, cfg.op_lag, recording, reaction)
    rec, base_split, n_fit = bases[lag]
    timing["base_fit"] = time.perf_counter() - t0
    # ---- selection
    t0 = time.perf_counter()
    sel = select_effects(base_split, rec.op, rec.pv, cfg.candidates, rule=rule, seed=seed,
                         effort=plan["confirm"], screen_effort=plan["screen"],
                         n_confirm=plan["n_confirm"], jobs=cfg.jobs, coarse=q, fast=fast,
                         progress=lambda s: say(f"{rec.name}: {s}"), executor=ex)
    timing["selection"] = time.perf_counter() - t0
    timing["per_candidate"] = timing["selection"] / max(len(sel.candidates), 1)
    timing["candidate_fits"] = len(sel.candidates)
    final_split = sel.final
    # ---- whole-record refits (the base and the final model side by side)
    t0 = time.perf_counter()
    todo = [(base_split, rec, seed + 1, "fast", fast)]
    if final_split is not base_split:
        todo.append((final_split, rec, seed + 2, "fast", fast))
    refits = pool_map(ex, _refit_task, todo)
    base, final = refits[0], refits[-1]
    timing["full_refit"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    mm = _locate(rec, base)
    mm_final = mm if final is base else _locate(rec, final)
    timing["locate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    say(f"{rec.name}: friction verdict")
    fv = _friction_stage(rec, recording, _Fits(base, final, mm, mm_final), cfg, executor=ex)
    timing["friction_verdict"] = time.perf_counter() - t0
    return _Stages(rec, base_split, sel, fv, lag, align, timing)


def _resolve_op_lag(op_lag) -> tuple[int, ...]:
    """The OP lags (samples) whose base fits ``op_lag`` asks for."""
    if isinstance(op_lag, str) and op_lag == "auto":
        return (0, 1)
    if isinstance(op_lag, (int, np.integer)) and not isinstance(op_lag, bool) and op_lag in (0, 1):
        return (int(op_lag),)
    raise ValueError(f"op_lag must be 'auto', 0 or 1 (samples between the logged OP and the PV it acts on), "
                     f"got {op_lag!r}")


def _base_task(args: tuple[Recording, _Config]):
    rec, cfg = args
    T = len(rec)
    n_fit = T - int(round(float(cfg.holdout) * T))
    _check_fit_part(rec, n_fit, cfg.holdout)
    st = ModelStructure(cfg.plant, cfg.actuator, (), _data_scales(rec, n_fit, cfg.saturation), n_sub=cfg.n_sub)
    base, _ = fit_with_friction(st, rec.op, rec.pv, n_fit, rng=cfg.seed, effort=cfg.plan["base"], coarse=cfg.q,
                                fast=cfg.fast)
    return rec, base, n_fit


#: The fitted part's PV must take at least this many distinct values (a frozen or coarsely
#: quantised transmitter, or a loop at rest, leaves nothing to identify).
MIN_PV_LEVELS = 3


def _check_fit_part(rec: Recording, n_fit: int, holdout: float) -> None:
    """Refuse a fitted part too short, or one over which the PV does not move (ValueError saying what to do)."""
    if n_fit < 40:
        raise ValueError(f"{rec.name}: only {n_fit} samples to fit after the holdout of {float(holdout):g}; need "
                         f">= 40: lower the holdout (--holdout 0.1, or 0 to fit the whole record) or use a "
                         f"longer record")
    levels = np.unique(rec.pv[:n_fit])
    if len(levels) < MIN_PV_LEVELS:
        shown = ", ".join(f"{v:.6g}" for v in levels)
        raise ValueError(f"{rec.name}: the PV takes only {len(levels)} value(s) ({shown}) over the fitted part "
                         f"(samples 0-{n_fit - 1} of {len(rec)}): a frozen or coarsely quantised transmitter, or a "
                         f"loop at rest, leaves nothing to identify; use a stretch where the PV moves (or a "
                         f"finer PV tag)")


def _base_fits(recording: Recording, lags: tuple[int, ...], cfg: _Config, executor,
               say: Callable[[str], None]) -> dict[int, tuple[Recording, FitResult, int]]:
    """Base fit (with friction, fit part) of the record paired at each OP lag: ``{lag: (rec, fit, n_fit)}``."""
    args = [(recording.with_op_lag(lag), cfg) for lag in lags]
    say(f"{recording.name}: fitting the base model ({cfg.plant} + {cfg.actuator}"
        + ("; OP paired with the same and with the next PV sample)" if len(lags) > 1 else ")"))
    return dict(zip(lags, pool_map(executor, _base_task, args)))


def _choose_op_lag(bases: dict[int, tuple[Recording, FitResult, int]], rule: SelectionRule,
                   asked, recording: Recording, reaction: dict | None) -> tuple[int, dict]:
    """The OP lag to diagnose with, and the test behind it (JSON-ready).

    ``op_lag='auto'``: the controller's reaction to PV moves (:func:`~.pairing.controller_reaction`)
    decides when it is clear; otherwise the base model fitted both ways does (the pairing of the lower
    information criterion, 1 only when it is lower by more than ``rule.ic_margin``).
    """
    if asked != "auto":
        lag = next(iter(bases))
        return lag, {"asked": asked, "chosen": lag, "tested": False}
    if reaction is None:          # the process sign comes from the base model (record paired as logged)
        reaction = controller_reaction(recording.op, recording.pv, process_gain_sign(bases[0][1].physical))
    test: dict = {"asked": asked, "tested": True, "controller_reaction": reaction}
    if reaction["op_lag"] is not None:
        lag = int(reaction["op_lag"])
        test.update(chosen=lag, method="controller reaction")
        return lag, test
    from .fit import effective_n
    f0, f1 = bases[0][1], bases[1][1]
    n_eff = effective_n(f0.residual[:f0.n_fit])
    # a difference of logs: the ratio of squares underflows for tiny errors (PV in tiny units)
    d_ic = float(2.0 * n_eff * (np.log(max(f1.rmse, 1e-300)) - np.log(max(f0.rmse, 1e-300))))
    lag = 1 if d_ic < -rule.ic_margin else 0
    test.update(chosen=lag, method="model fit", delta_ic=d_ic, n_eff=float(n_eff),
                rmse_fit_part={"0": float(f0.rmse), "1": float(f1.rmse)})
    return lag, test


def _check_arguments(recording: Recording, plant: str, actuator: str, holdout: float,
                     candidates: Sequence[str] | str | None) -> tuple[str, dict, tuple[str, ...]]:
    """Check the arguments of :func:`diagnose`: the plant (``'auto'`` resolved), its choice, the candidates."""
    if not isinstance(recording, Recording):
        raise TypeError("diagnose() needs a Recording (see load_recording)")
    plant, plant_choice = resolve_plant(plant, recording.name, recording.columns.get("pv"), recording.op,
                                        recording.pv, float(recording.dt or 1.0))
    if plant not in PLANTS:
        raise ValueError(f"unknown plant {plant!r}; choose 'auto' or one of {', '.join(PLANTS)}")
    if actuator not in ACTUATORS:
        raise ValueError(f"unknown actuator {actuator!r}; choose 'valve' or 'pump'")
    if not 0.0 <= float(holdout) <= 0.6:
        raise ValueError(f"holdout must be a fraction between 0 and 0.6, got {holdout!r}")
    known = candidate_effects()
    if isinstance(candidates, str):              # 'leak' or 'leak,overflow', as the CLI's --effects
        candidates = [c.strip() for c in candidates.split(",") if c.strip()]
    cands = tuple(known if candidates is None else candidates)
    for c in cands:
        if c not in known:
            raise ValueError(f"unknown effect {c!r}; candidates are {', '.join(known)}")
    return plant, plant_choice, cands


def _check_seed_and_range(seed, saturation) -> None:
    """Refuse a seed that is not a whole number >= 0 and a sensor range that is not ``(lo, hi)`` with lo < hi."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a whole number >= 0, got {seed!r}")
    if saturation is None or (isinstance(saturation, str) and saturation == "auto"):
        return
    try:
        lo, hi = (float(v) for v in saturation)
    except (TypeError, ValueError):
        raise ValueError(f"saturation must be 'auto', None or a pair (lo, hi) of the PV's sensor range, "
                         f"got {saturation!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"saturation (lo, hi) must be finite with lo < hi (the PV's sensor range), got {saturation!r}")


def _dt(rec: Recording) -> float:
    """Sample time of ``rec`` [s] (:class:`Recording` always sets it)."""
    assert rec.dt is not None
    return rec.dt


def _data_scales(rec: Recording, n_fit: int, saturation) -> DataScales:
    """Scales of the fit part; with ``'auto'`` saturation the sensor range seen on the whole record."""
    sc = DataScales.from_signals(rec.op[:n_fit], rec.pv[:n_fit], rec.dt, saturation=saturation)
    if saturation == "auto":
        full = DataScales.from_signals(rec.op, rec.pv, rec.dt, saturation="auto")
        sc = DataScales(**{**sc.__dict__, "sat_hi": full.sat_hi, "sat_lo": full.sat_lo})
    return sc


class _Fits(NamedTuple):
    """The base and final models on the whole record, with where each misses."""

    base: FitResult                 # base model, whole record
    final: FitResult                # final model, whole record
    mismatch: MismatchReport        # of ``base``
    mismatch_final: MismatchReport  # of ``final``


class _FrictionStage(NamedTuple):
    """Outcome of the friction stage of :func:`diagnose`: the readings the friction verdict is decided from."""

    tests: _FrictionTests                    # the model-based friction tests
    horch: dict | None                       # Horch's test (None for a pump)
    assessment: StictionAssessment | None    # the stiction methods combined (None for a pump)
    base: FitResult                 # base model, whole record (the nested optimum if it was the final one)
    final: FitResult                # final model, whole record
    mismatch: MismatchReport        # of ``base``
    mismatch_final: MismatchReport  # of ``final``


def _friction_stage(rec: Recording, logged: Recording, fits: _Fits, cfg: _Config, executor=None) -> _FrictionStage:
    """Friction tests, Horch's test and the combined assessment; the final model it keeps.

    The model fits read ``rec`` (the record as paired for the model, :meth:`Recording.with_op_lag`);
    the data-driven methods read ``logged``, the record as it was logged (``rec`` itself when the
    pairing is the model's own), so their evidence does not move with the pairing chosen.
    """
    base, final, mm, mm_final = fits
    tests = _friction_tests(final, rec, mm, cfg, executor=executor)
    horch = assessment = None
    if cfg.actuator == "valve" and tests.free_run is not None:
        horch = horch_ccf(logged.op, logged.pv, _dt(logged), cfg.plant)
        assessment = _assess(rec, logged, cfg.plant, tests, executor)
    if tests.final is not final:
        same = final is base
        final = tests.final
        if same:
            base = final
            mm = _locate(rec, base)
        mm_final = mm if final is base else _locate(rec, final)
    return _FrictionStage(tests, horch, assessment, base, final, mm, mm_final)


def _explanations(rec: Recording, sel: Selection, base: FitResult, final: FitResult,
                  mm: MismatchReport) -> list[str]:
    """One paragraph per effect added (in the order added), or why none was."""
    expl: list[str] = []
    sc_f = final.structure.scales
    masks = condition_masks(rec.op, rec.pv, rec.sp, _dt(rec), mm.window, sc_f.sat_hi, sc_f.sat_lo)
    fits_by_effect = {c.effect: c for c in sel.candidates if c.accepted}
    chain = [base]
    for e in sel.effects:
        chain.append(fits_by_effect[e].fit)
    for i, e in enumerate(sel.effects):
        before_split, after_split = chain[i], chain[i + 1]
        after = final if i == len(sel.effects) - 1 else after_split
        before = base if i == 0 else before_split
        mm_i = mm if i == 0 else _locate(rec, before_split)
        expl.append(explain_effect(e, before, after, mm_i, masks=masks))
    if not sel.effects:
        best = min(sel.candidates, key=lambda c: c.delta_ic).effect if sel.candidates else None
        expl.append(explain_none(base, mm, best))
    return expl


#: Whole-record fit [%] (NRMSE, 100 perfect, 0 the record's mean) below which the final model explains too
#: little of the record for its effects and verdict to be read.
POOR_FIT = 0.0


def _note_poor_fit(expl: list[str], final: FitResult, plant: str) -> None:
    """Append a caution when the final model explains the record worse than its mean does."""
    fp = float(final.fit_percent_all)
    if not (fp < POOR_FIT):
        return
    expl.append(f"Caution: the final model fits the record worse than a constant at its mean (fit {fp:.3g} %), "
                f"so the effects named and the friction verdict above do not describe it. Check that the plant "
                f"model suits the loop (--plant; now '{plant}': the tank reads the PV as the level above its "
                f"outlet, so a PV with a large offset or in odd units does not fit it), the PV's units and the "
                f"output's range (--op-range).")


# --------------------------------------------------------------------------- many
def _diagnose_job(args):
    path, load_kw, diag_kw, out_json, out_report = args
    from .recording import load_recording
    t0 = time.perf_counter()
    try:
        rec = load_recording(path, **load_kw)
        res = diagnose(rec, **diag_kw)
        d = res.to_dict()
        if out_json:
            from .report import write_json
            write_json(d, out_json)
        if out_report:
            from .report import write_report
            write_report(res, out_report)
        return {"path": str(path), "ok": True, "row": res.summary_row(), "result": d,
                "seconds": time.perf_counter() - t0}
    except (RecordingError, ValueError) as e:
        return {"path": str(path), "ok": False, "error": str(e),
                "seconds": time.perf_counter() - t0}
    except Exception as e:  # pragma: no cover - an internal error must not stop the batch
        return {"path": str(path), "ok": False,
                "error": f"internal error: {type(e).__name__}: {e}",
                "seconds": time.perf_counter() - t0}


def diagnose_many(paths: Sequence[str], jobs: int = 2, load_kw: dict | None = None,
                  diag_kw: dict | Callable[[str], dict] | None = None, json_dir: str | None = None,
                  report_dir: str | None = None,
                  progress: Callable[[str], None] | None = None) -> list[dict]:
    """Diagnose many recording files in full, on the local executor of the batch engine.

    A library function for a list of files each diagnosed in full (no screening; per-file settings).
    A folder of loops is diagnosed by the batch engine itself, :func:`valve_gym.fleet.run_fleet`
    (``valve-gym diagnose DIR``: screening, full diagnosis of the oscillating loops); its local
    executor (:func:`valve_gym.fleet.runner.local_results`: this process for ``jobs`` 1, else worker
    processes) runs these diagnoses too.

    Parameters
    ----------
    paths : sequence of CSV paths
    jobs : int, worker processes (the kernel threads are shared out between them)
    load_kw : dict, keyword arguments of :func:`load_recording` (columns, op_range, ...)
    diag_kw : dict, keyword arguments of :func:`diagnose` (plant, actuator, ...); may
        be a callable ``path -> dict`` for per-file settings
    json_dir, report_dir : str, optional, one JSON / report folder per recording
    progress : callable(str), told ``[i/n] name: ...`` as each one finishes

    Returns
    -------
    list of dict, in the order of ``paths``: ``path``, ``ok``, and either
    ``row`` (summary row) and ``result`` (the JSON dict) or ``error``.
    """
    from ..fleet.runner import local_results

    load_kw = dict(load_kw or {})
    tasks = []
    for p in paths:
        dk = diag_kw(p) if callable(diag_kw) else dict(diag_kw or {})
        dk.setdefault("jobs", 1)
        stem = os.path.splitext(os.path.basename(str(p)))[0]
        oj = os.path.join(json_dir, stem + ".json") if json_dir else None
        orp = os.path.join(report_dir, stem) if report_dir else None
        tasks.append((str(p), load_kw, dk, oj, orp))
    out: list[dict | None] = [None] * len(tasks)
    n = len(tasks)
    done = 0
    t0 = time.perf_counter()
    for i, r, err in local_results(_diagnose_job, tasks, jobs):
        if i < 0:
            continue
        if err is not None:
            r = {"path": tasks[i][0], "ok": False, "error": f"worker lost ({type(err).__name__}: {err})",
                 "seconds": math.nan}
        out[i] = r
        done += 1
        if progress:
            name = os.path.basename(r["path"])
            if r["ok"]:
                row = r["row"]
                msg = (f"[{done}/{n}] {name}: effects={row['effects']}, stiction={row['stiction']}, "
                       f"RMSE {row['base_rmse']:.4g} -> {row['final_rmse']:.4g} "
                       f"({r['seconds']:.1f} s; elapsed {time.perf_counter() - t0:.0f} s)")
            else:
                msg = f"[{done}/{n}] {name}: ERROR {r['error']}"
            progress(msg)
    return out  # type: ignore[return-value]
