"""The combined stiction assessment inside the diagnosis, and the S/J estimates with intervals."""
import numpy as np
import pytest

from valve_gym.diagnosis import diagnose
from valve_gym.diagnosis.diagnose import coarse_factor
from valve_gym.diagnosis.stiction import assess_stiction, default_model
from valve_gym.diagnosis.stiction.hammerstein import SizeEstimate, _profile, profile_interval, widen
from valve_gym.diagnosis.stiction.loops import LoopSpec, simulate_loop

STICKY = LoopSpec(process="integrating", valve="kano", S=0.05, J=0.02, k_i=0.02, Kc=4.0, Ti=60.0, Ts=1.0,
                  theta=2.0, noise=0.0003, tau_v=0.2, n=900, sp_step=0.02)


@pytest.fixture(scope="module")
def sticky_result():
    return diagnose(simulate_loop(STICKY, seed=3), plant="integrating", candidates=(), effort="fast")


@pytest.mark.slow
def test_diagnosis_reports_probability_and_sizes(sticky_result):
    s = sticky_result.to_dict()["stiction"]
    for k in ("probability", "verdict", "S", "J", "S_interval", "J_interval", "evidence", "model_based_present"):
        assert k in s
    assert 0.0 <= s["probability"] <= 1.0
    assert s["verdict"] in ("stiction", "no stiction", "undecided")
    # the public verdict: the combination says stiction, or the free-run model-based verdict finds friction
    # that the k-step test does not contradict, or the k-step test finds a band that matters on its own
    k = s["kstep_delta_ic"]
    assert s["present"] is (s["verdict"] == "stiction" or (s["model_based_present"] and k < 0)
                            or (k < -2 and max(s["band"], s["kstep_band"]) >= s["band_needed"]))
    assert {e["method"] for e in s["evidence"]} == {"horch", "bicoherence", "ellipse", "waveform", "episodes",
                                                   "hammerstein", "kstep"}
    # the k-step friction test ran beside the free-run one (integrating loop, valve, no measurement effect)
    assert s["kstep_horizon"] == 60 and np.isfinite(s["kstep_delta_ic"])
    ks = next(e for e in s["evidence"] if e["method"] == "kstep")
    assert ks["applicable"] and ks["value"] == pytest.approx(np.arcsinh(-k / 2))
    assert "kstep" not in s["features"]            # read by the public verdict, not by the logistic model
    lo, hi = s["S_interval"]
    assert lo <= s["S"] <= hi
    jlo, jhi = s["J_interval"]
    assert jlo <= s["J"] <= jhi


def test_clear_sticky_integrating_loop_is_stiction_with_right_size(sticky_result):
    s = sticky_result.stiction
    assert s["verdict"] == "stiction" and s["probability"] > 0.6
    lo, hi = s["S_interval"]
    assert lo <= STICKY.S * 1.3 and hi >= STICKY.S * 0.7          # the interval reaches the true band


def test_quiet_healthy_loop_is_not_stiction():
    spec = LoopSpec(process="foptd", valve="linear", S=0.0, J=0.0, K=1.5, tau=40.0, theta=5.0, Kc=0.8, Ti=40.0,
                    noise=0.002, noise_pole=0.6, load=0.004, n=700)
    rec = simulate_loop(spec, seed=4)
    a = assess_stiction(rec.op, rec.pv, float(rec.dt or 1.0), "first_order", sp=rec.sp,
                        verdict={"tested": True, "present": False, "delta_ic": 5.0, "band": 0.001,
                                 "band_needed": 0.01})
    assert a.verdict != "stiction" and a.probability < 0.5


def test_default_model_is_fitted_and_coarse_factor():
    m = default_model()
    assert m.n_train > 50 and any(c != 0 for c in m.coef)
    assert coarse_factor(1800) == 1 and coarse_factor(3600) == 3
    with pytest.raises(ValueError, match="coarse"):
        diagnose(simulate_loop(STICKY, seed=3), plant="integrating", candidates=(), coarse=0)



@pytest.fixture(scope="module")
def slip_fit():
    """The slip-jump fit the diagnosis sizes the sticky loop with (caught on its way to the profile)."""
    import valve_gym.diagnosis.stiction.assess as assess

    rec = simulate_loop(STICKY, seed=3)
    seen = {}
    orig = assess.slip_jump_profile

    def spy(fit, u, y, **kw):
        seen["fit"] = fit
        return orig(fit, u, y, **kw)

    mp = pytest.MonkeyPatch()
    mp.setattr(assess, "slip_jump_profile", spy)
    try:
        diagnose(rec, plant="integrating", candidates=(), effort="fast")
    finally:
        mp.undo()
    assert seen.get("fit") is not None
    return seen["fit"], rec


@pytest.mark.slow
def test_profile_reoptimises_the_other_parameters(slip_fit):
    fit, rec = slip_fit
    st = fit.structure
    pr = _profile(fit, rec.op, rec.pv, 9, 5)
    i_s = st.index("S")
    W = np.repeat(fit.w[None, :], len(pr.s), axis=0)          # the other parameters fixed at the optimum
    W[:, i_s] = st.params[i_s].coord(pr.s)
    Y = st.simulate(W, np.asarray(rec.op))[: fit.n_fit]
    fixed = np.sum((Y - np.asarray(rec.pv)[: fit.n_fit, None]) ** 2, axis=0)
    assert np.all(pr.sse <= fixed * (1 + 1e-9))                 # re-optimising never does worse
    assert np.any(pr.sse < 0.9 * fixed)                         # and away from the optimum it does better
    est, s_err = profile_interval(fit, rec.op, rec.pv, 9, 5)
    assert est.S_lo <= est.S <= est.S_hi and est.J_lo <= est.J <= est.J_hi and s_err >= 0.0
    # the two sides of the optimum run side by side in worker processes: the same profile
    from valve_gym.diagnosis.model import process_pool

    with process_pool(2) as ex:
        pr2 = _profile(fit, rec.op, rec.pv, 9, 5, map_fn=ex.map)
    assert np.array_equal(pr2.s, pr.s) and np.array_equal(pr2.w, pr.w) and np.array_equal(pr2.sse, pr.sse)


def test_widen_adds_window_error_and_discrepancy():
    e = SizeEstimate("hammerstein", 0.05, 0.04, 0.06, 0.02, 0.01, 0.03)
    assert widen(e, 0.0, 0.0, 0.0) == e
    w = widen(e, 0.01 / 1.645, 0.0, 0.0)                        # 90 % half-width 0.01 in quadrature
    assert w.S_lo == pytest.approx(0.05 - np.hypot(0.01, 0.01)) and w.S_hi == pytest.approx(0.05 + np.hypot(0.01, 0.01))
    w = widen(e, 0.0, np.log(2.0), np.log(3.0))
    assert (w.S_lo, w.S_hi, w.J_lo, w.J_hi) == pytest.approx((0.02, 0.12, 0.01 / 3, 0.09))
    assert widen(e, 1.0, 0.0, 0.0).S_lo == 0.0                  # never below zero


def test_two_size_methods_combine_on_the_log_scale_with_the_union_interval():
    from valve_gym.diagnosis.stiction.assess import combine_size_estimates

    nan = float("nan")
    ham = SizeEstimate("hammerstein", 0.04, 0.02, 0.08, 0.01, 0.005, 0.02)      # log half-width ln 2
    ell = SizeEstimate("ellipse", 0.06, 0.03, 0.12, nan, nan, nan)              # the same width: equal weights
    s, agree = combine_size_estimates([ham, ell])
    assert agree is True and s.method == "hammerstein+ellipse"
    assert s.S == pytest.approx(np.sqrt(0.04 * 0.06)) and (s.S_lo, s.S_hi) == (0.02, 0.12)
    assert (s.J, s.J_lo, s.J_hi) == (0.01, 0.005, 0.02)                        # J: the slip-jump block's
    narrow = ell._replace(S_lo=0.055, S_hi=0.0655)                              # a tighter ellipse weighs more
    assert combine_size_estimates([ham, narrow])[0].S > 0.055
    far = ell._replace(S=0.3, S_lo=0.2, S_hi=0.4)
    s, agree = combine_size_estimates([ham, far])
    assert agree is False and (s.S_lo, s.S_hi) == (0.02, 0.4)                  # disagreeing: the union, flagged
    assert combine_size_estimates([ham]) == (ham, None)


def _benchmark_loop(repo_module, i: int, seed=None):
    """Regulation loop ``i`` of the benchmark (``benchmarks/sizes_on_benchmark_loops.py``) as a Recording."""
    from valve_gym.diagnosis import Recording

    mod = repo_module("benchmarks/sizes_on_benchmark_loops.py", "sizes_on_benchmark_loops")
    loop = mod.benchmark_loops(36, seed)[i]
    return loop, Recording(t=loop["t"], op=loop["op"], pv=loop["pv"], sp=loop["sp"], dt=loop["dt"],
                           name=loop["name"])


@pytest.mark.slow
def test_kstep_test_finds_a_sticky_valve_under_a_drifting_load(repo_module):
    """The compensator benchmark's cycling Choudhury valve (S 9.3 %) under its Ornstein-Uhlenbeck load: the
    free-run friction test is blind to it (the load's error outweighs the friction's), the k-step one is not
    (docs/diagnosis.md, 'The k-step friction test')."""
    loop, rec = _benchmark_loop(repo_module, 25)
    assert loop["name"] == "choudhury_severe_25" and loop["S_true"] > 0.09
    s = diagnose(rec, plant="tank", candidates=(), effort="fast").stiction
    assert s["delta_ic"] > 0 and not s["model_based_present"]
    assert s["kstep_delta_ic"] < -2
    assert s["kstep_rmse"]["friction"] < 0.95 * s["kstep_rmse"]["frictionless"]
    ks = next(e for e in s["evidence"] if e["method"] == "kstep")
    assert ks["verdict"] == "stiction"              # its own verdict; the public one reads it as a check only


@pytest.mark.slow
def test_kstep_fit_that_holds_the_valve_still_does_not_call_alone(repo_module):
    """A sticky Riihilahti valve under the benchmark's Ornstein-Uhlenbeck load: neither the free run (criterion up
    with friction) nor the methods combined call it.  Where the k-step predictions want friction (criterion below
    -2), the band is about 15 % of the stroke against an output working range of 5.5 %: the fitted valve never
    moves (the true one moves hundreds of times), so the fit explains the level without the output's moves, as it
    would a quiet healthy loop with coloured noise, and the public verdict does not call it on that fit alone (the
    rule itself: ``test_friction_moves_and_the_evidence_of_a_still_valve``)."""
    loop, rec = _benchmark_loop(repo_module, 14)
    assert loop["name"] == "riihilahti_sticky_14" and loop["label"] == 1
    s = diagnose(rec, plant="tank", candidates=(), effort="fast").stiction
    assert s["delta_ic"] > 0 and not s["model_based_present"] and s["verdict"] != "stiction"
    assert s["present"] is False
    if s["kstep_delta_ic"] < -2:            # the k-step fit wants friction: a band that holds the valve still
        assert s["kstep_band"] > s["op_working_range"] > 0.05 and s["kstep_slips"] == 0


def test_kstep_fit_band_calls_a_sticky_valve_the_free_run_fit_sets_free():
    """A Choudhury valve (S 4.6 %) on an integrating loop, loop 44 of ``validate_stiction.py``'s textbook loops:
    the free-run friction fit puts the band at almost zero and raises the criterion, the methods combined do not
    call it, and the k-step fit finds a band close to the true S; the public verdict reads that fit's own band."""
    from valve_gym.diagnosis.stiction.loops import random_spec

    spec = random_spec(np.random.default_rng(50_044), True)
    assert spec.valve == "choudhury" and spec.process == "integrating" and spec.S > 0.04
    s = diagnose(simulate_loop(spec, seed=44), plant="integrating", candidates=()).stiction
    assert s["delta_ic"] > 0 and s["band"] < 0.1 * s["band_needed"] and s["verdict"] != "stiction"
    assert s["kstep_delta_ic"] < -2 and s["kstep_band"] >= s["band_needed"]
    assert abs(s["kstep_band"] / spec.S - 1.0) < 0.25
    assert s["present"] is True
    assert "missed it, and the verdict is that the valve sticks" in s["explanation"]


def test_naming_and_verdict_conflict_is_reported():
    """A slip-jump term named while the verdict is no: flagged in the paragraph and in ``naming_agrees``."""
    from dataclasses import replace

    from valve_gym.diagnosis.explain import explain_naming_conflict
    from valve_gym.diagnosis.stiction import StictionAssessment
    from valve_gym.diagnosis.verdict import FreeRunTest, FrictionVerdict, decide_friction

    nan = float("nan")
    a = StictionAssessment(0.03, "no stiction", nan, nan, (nan, nan), (nan, nan), None)
    v = FrictionVerdict(tested=True, present=False, combined=a, naming_agrees=False)
    c = explain_naming_conflict(v)
    assert c.startswith(" Caution: the stiction verdict is no (probability of stiction 0.03)") and "valve test" in c
    assert explain_naming_conflict(replace(v, naming_agrees=True)) == ""
    pump = FrictionVerdict.untested()
    assert explain_naming_conflict(pump) == "" and pump.naming_agrees is None
    v = replace(v, verdict_source="stem")
    assert "recorded valve position follows the output" in explain_naming_conflict(v)
    # decide_friction: naming agrees unless the slip-jump effect is named and the verdict is no
    t = FreeRunTest(parameters={"model": "slip_jump", "S": 0.0, "J": 0.0, "band": 0.0}, delta_ic=3.0,
                    significant=False, band=0.0, slips=0, band_needed=0.01, op_working_range=0.2, n_eff=100.0,
                    frictionless_model="tank + valve", frictionless_rmse=1.0, friction_rmse=1.0, compared={})
    sticks = replace(a, probability=0.9, verdict="stiction")
    for named, assessment, present, agrees in ((True, a, False, False), (False, a, False, True),
                                               (True, sticks, True, True), (False, sticks, True, True)):
        v = decide_friction(t, None, assessment, None, named_slip_jump=named)
        assert v.present is present and v.naming_agrees is agrees

def test_diagnosis_reports_whether_naming_agrees(sticky_result):
    s = sticky_result.to_dict()["stiction"]
    assert s["naming_agrees"] is True               # nothing named (no candidates): no conflict


def test_report_states_both_model_based_readings():
    """The report's verdict line names the free-run reading and the k-step one, which can decide alone."""
    from valve_gym.diagnosis.report import _verdict_basis

    t = _verdict_basis({"probability": 0.03, "verdict": "no stiction", "model_based_present": False,
                        "kstep_delta_ic": -25.3, "kstep_horizon": 60})
    assert "free-run model-based test: no friction" in t
    assert "on 60-sample-ahead predictions friction lowers the criterion (-25.3)" in t


def test_a_friction_fit_whose_valve_never_slips_is_no_sticking_valve():
    """Healthy loop 3 of ``textbook_limit_cycles.py``: a sphere sampled at 0.5 s whose output moves only 1.2 % (its
    moves answer strongly coloured measurement noise).  A paper-friction valve with a band wider than those moves
    lowers the criterion, but the fitted valve never moves: no model-based call, and no model-based evidence."""
    from dataclasses import replace

    from valve_gym.diagnosis.stiction.loops import random_spec

    rng = np.random.default_rng(130_006)
    spec = random_spec(rng, False, process="tank", n=1800, disturbance="none")
    op_noise = float(np.exp(rng.uniform(np.log(3e-4), np.log(1e-2))))
    spec = replace(spec, noise=op_noise / spec.Kc)
    assert spec.valve == "linear" and spec.shape == "sphere" and spec.noise_pole > 0.85
    res = diagnose(simulate_loop(spec, seed=130_006, name="healthy_3"), plant="tank", candidates=())
    s = res.stiction
    assert s["delta_ic"] < -2 and s["band"] >= s["band_needed"] and s["op_working_range"] < 0.02
    assert s["slips"] == 0 and s["model_based_present"] is False
    assert "the fitted valve never moves" in s["explanation"]
    ham = next(e for e in res.stiction["evidence"] if e["method"] == "hammerstein")
    assert ham["applicable"] is False and "slips 0 time(s)" in ham["reason"]


def test_friction_moves_and_the_evidence_of_a_still_valve():
    from valve_gym.diagnosis.stiction.combine import public_present
    from valve_gym.diagnosis.stiction.hammerstein import MIN_SLIPS, SEIZED_TRAVEL, friction_moves, hammerstein_evidence

    assert not friction_moves(MIN_SLIPS - 1, 0.5 * SEIZED_TRAVEL) and friction_moves(MIN_SLIPS, 0.0)
    assert friction_moves(0, SEIZED_TRAVEL)          # a valve that stays put over a long travel is seized
    v = {"tested": True, "present": False, "delta_ic": -12.0, "band": 0.03, "band_needed": 0.01,
         "op_working_range": 0.02}
    assert hammerstein_evidence({**v, "slips": 5}).applicable
    still = hammerstein_evidence({**v, "slips": 0})
    assert not still.applicable and "slips 0 time(s)" in still.reason
    assert hammerstein_evidence({**v, "slips": 0, "op_working_range": 0.2}).applicable
    # a friction fit that does not pay is evidence against friction whether its valve moves or not
    assert hammerstein_evidence({**v, "delta_ic": 6.0, "slips": 0}).applicable
    # the k-step branch of the public verdict asks the same of the k-step fit's valve
    k = {"tested": True, "model_based_present": False, "kstep_delta_ic": -9.0, "band": 0.001,
         "kstep_band": 0.03, "band_needed": 0.01, "op_working_range": 0.02}
    assert public_present("no stiction", {**k, "kstep_slips": 4}) is True
    assert public_present("no stiction", {**k, "kstep_slips": 1}) is False
    assert public_present("no stiction", {**k, "kstep_slips": 0, "op_working_range": 0.3}) is True
