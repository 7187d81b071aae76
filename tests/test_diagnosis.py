"""Tests of the diagnosis fitter and selection on synthetic recordings with known truth.

Tolerances: process parameters (q_max/A, k_out/A, K, T) within 5 %, the dead
band within 0.001 of stroke, slip-jump S and J within 15 %; every fit is the
free-run fit of :class:`ModelFitter` with the default search.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from valve_gym.core import initial_state, simulate
from valve_gym.diagnosis import ModelFitter, Recording, diagnose
from valve_gym.diagnosis.diagnose import JSON_SCHEMA_KEYS
from valve_gym.diagnosis.fit import effective_n, fit_percent, information_criterion
from valve_gym.diagnosis.model import DataScales, ModelStructure
from valve_gym.diagnosis.synthetic import make_case, make_recording
from valve_gym.params import FirstOrderParams, ModelParams, ValveParams


def rel(a, b):
    return abs(a - b) / abs(b)


# --------------------------------------------------------------------------- fitting
def test_tank_and_dead_band_recovered():
    case = make_case("none", seed=12, n=600)
    f = ModelFitter(plant="tank", seed=0).fit(case.recording)
    t, p = case.truth, f.physical_
    assert rel(p["process.q_max"], t["process.q_max"] / t["process.area"]) < 0.05
    assert rel(p["process.k_out"], t["process.k_out"] / t["process.area"]) < 0.05
    assert abs(p["valve.e_dead"] - t["valve.e_dead"]) < 0.001
    assert f.rmse_ < 1.2 * 0.004            # the measurement noise
    assert f.fit_percent_ > 95
    assert f.y_sim_.shape == (600,)
    assert f.params_.process_kind == "tank"
    assert np.isfinite(f.cost_) and f.cost_ > 0


def test_slip_jump_recovered():
    case = make_case("slip_jump", seed=12, n=800)
    f = ModelFitter(plant="tank", effects=("slip_jump",), seed=0).fit(case.recording)
    t, p = case.truth, f.physical_
    assert rel(p["slip_jump.S"], t["slip_jump.S"]) < 0.15
    assert rel(p["slip_jump.J"], t["slip_jump.J"]) < 0.15


def test_first_order_with_friction_recovered():
    rng = np.random.default_rng(0)
    T, dt = 800, 2.0
    u = np.repeat(rng.uniform(0.3, 0.7, T // 40), 40) + 0.003 * rng.normal(size=T)
    p = ModelParams(valve=ValveParams(tau=0.1, v_max=np.inf, e_dead=0.01, z_max=0.05),
                    process=FirstOrderParams(K=2.0, T=15.0, b=1.0), process_kind="first_order",
                    dt=0.1)
    y = simulate(p, u, state=initial_state(p, 1, level=2.0, h=u[0]), n_sub=20).y[:, 0]
    y = y + 0.01 * rng.normal(size=T)
    rec = Recording(t=np.arange(T) * dt, op=u, pv=y, dt=dt)
    f = ModelFitter(plant="first_order").fit(rec)
    q = f.physical_
    assert rel(q["process.K"], 2.0) < 0.05
    assert rel(q["process.T"], 15.0) < 0.05
    assert abs(q["process.b"] - 1.0) < 0.05
    assert abs(q["valve.e_dead"] - 0.01) < 0.001
    assert abs(q["init.level"] - 2.0) < 0.05


def test_holdout_and_predict():
    rec = make_recording("none", seed=13, n=500)
    f = ModelFitter(plant="tank", holdout=0.3, effort="fast").fit(rec)
    assert f.result_.n_fit == 350
    assert np.isfinite(f.holdout_rmse_) and f.holdout_rmse_ < 0.01
    y = f.predict(rec)
    assert y.shape == (500,) and fit_percent(rec.pv, y) > 90
    with pytest.raises(ValueError, match="holdout"):
        ModelFitter(holdout=1.5).fit(rec)
    with pytest.raises(RuntimeError, match="not fitted"):
        ModelFitter().predict(rec)


def test_structure_rejects_unidentifiable_effects():
    sc = DataScales.from_signals(np.linspace(0.2, 0.6, 100), np.linspace(1, 2, 100), 1.0)
    with pytest.raises(ValueError, match="leak"):
        ModelStructure("integrating", "valve", ("leak",), sc)
    with pytest.raises(ValueError, match="valve"):
        ModelStructure("tank", "pump", ("slip_jump",), sc)
    with pytest.raises(ValueError, match="positive level"):
        ModelStructure("tank", "valve", (), DataScales.from_signals(np.ones(5) * .5 + np.arange(5) * .01,
                                                                    np.arange(5) - 2.0, 1.0))


def test_information_criterion_and_effective_n():
    rng = np.random.default_rng(0)
    white = rng.normal(size=2000)
    assert effective_n(white) > 1500
    smooth = np.convolve(white, np.ones(50) / 50, mode="same")
    assert effective_n(smooth) < 200
    a = information_criterion(1.0, 100, 3, 1000)
    b = information_criterion(1.0, 100, 4, 1000)
    assert b - a == pytest.approx(np.log(100))


# --------------------------------------------------------------------------- selection
@pytest.fixture(scope="module")
def overflow_result():
    rec = make_recording("overflow", seed=32, n=600)
    return diagnose(rec, plant="tank", candidates=("overflow", "leak", "sensor_lag"),
                    validate=rec, effort="fast")


@pytest.mark.slow
def test_overflow_is_named(overflow_result):
    res = overflow_result
    assert res.effects == ["overflow"]
    assert res.final.rmse_all < 0.5 * res.base.rmse_all
    assert res.final_split.holdout_rmse < 0.5 * res.base_split.holdout_rmse
    assert res.explanation[0].startswith("Overflow")
    top = res.final.physical["overflow.L_max_pv"]
    assert abs(top - make_case("overflow", seed=32, n=600).truth["overflow.L_max"]) < 0.01


@pytest.mark.slow
def test_dead_time_is_named():
    # a dead time of a few seconds needs about 20 set-point moves to be told from a friction band at
    # the cheap search budget (at 600 samples it was named on 1 of 5 seeds): four consecutive seeds
    # at 1200 samples, at least three named alone, each with its dead time within 1 s
    named = 0
    for seed in range(20, 24):
        case = make_case("dead_time", seed=seed, n=1200)
        res = diagnose(case.recording, plant="tank", candidates=("dead_time", "leak", "overflow"), effort="fast")
        if res.effects == ["dead_time"]:
            named += 1
            assert abs(res.final.physical["dead_time.theta"] - case.truth["dead_time.theta"]) < 1.0
    assert named >= 3


def test_none_on_a_base_model_recording():
    rec = make_recording("none", seed=22, n=600)
    res = diagnose(rec, plant="tank", candidates=("overflow", "leak", "dead_time"),
                   effort="fast")
    assert res.effects == []
    assert "No candidate effect pays" in res.explanation[0]


def test_result_json_schema_and_validation(overflow_result):
    d = json.loads(overflow_result.to_json())
    assert set(JSON_SCHEMA_KEYS) <= set(d)
    assert d["effects"] == ["overflow"]
    for key in ("base", "final"):
        assert {"rmse", "fit_percent", "params"} <= set(d[key])
        assert d[key]["rmse"] > 0
    assert d["final"]["rmse"] < d["base"]["rmse"]
    assert isinstance(d["mismatch"], list) and d["mismatch"]
    for r in d["mismatch"]:
        assert {"t_start", "t_end", "conditions"} <= set(r) and r["t_end"] > r["t_start"]
    assert {"present", "parameters"} <= set(d["stiction"])
    assert isinstance(d["stiction"]["present"], bool)
    assert {"base_rmse", "final_rmse"} <= set(d["validation"])
    assert d["validation"]["final_rmse"] < d["validation"]["base_rmse"]
    # validated on its own recording: from the fitted initial state it is the fit itself
    v, res = d["validation"], overflow_result
    assert v["final_rmse_same_state"] == pytest.approx(res.final.rmse_all, rel=1e-9)
    assert v["base_rmse_same_state"] == pytest.approx(res.base.rmse_all, rel=1e-9)
    assert d["holdout"]["final_rmse"] <= d["holdout"]["base_rmse"]


def test_cascade_structure_and_sensor_range():
    t = np.arange(400.0)
    u = 0.3 + 0.2 * (np.sin(t / 40) > 0)
    y = np.minimum(5 + 0.001 * t + 6 * (np.sin(t / 40) > 0) * (1 - np.exp(-(t % 125) / 20)), 10.0)
    sc = DataScales.from_signals(u, y, 4.0)
    assert sc.sat_hi == 10.0 and sc.sat_lo is None
    st = ModelStructure("cascade", "pump", ("overflow",), sc)
    assert "c" in st.names and "L_max" in st.names and "dh0" not in st.names
    W = np.random.default_rng(0).random((8, len(st.params)))
    Y = st.simulate(W, u)
    assert Y.shape == (400, 8) and np.nanmax(Y) <= 10.0
    p = st.physical(W[0])
    assert {"schoukens.k1", "schoukens.k4", "overflow.spill_to_lower", "init.level2"} <= set(p)


def test_integrating_output_sign_is_fitted():
    rng = np.random.default_rng(5)
    T = 600
    u = np.clip(0.5 + np.cumsum(rng.normal(0, 0.01, T)), 0.3, 0.7)
    y = 50 - np.cumsum(0.8 * (u - 0.5)) + 0.02 * rng.normal(size=T)   # the valve drains
    rec = Recording(t=np.arange(T) * 1.0, op=u, pv=y, dt=1.0)
    f = ModelFitter(plant="integrating", friction=False, effort="fast").fit(rec)
    assert f.physical_["measurement.sign"] == -1.0
    assert rel(f.physical_["process.q_max"], 0.8) < 0.1
    assert f.fit_percent_ > 90


def test_fitter_simulations_are_the_same_in_kernel_threads():
    from valve_gym.diagnosis import model as mmod

    case = make_case("dead_time", seed=3, n=1500)
    r = case.recording
    st = ModelStructure("tank", "valve", ("dead_time", "sensor_lag"),
                        DataScales.from_signals(r.op, r.pv, r.dt))
    W = np.random.default_rng(1).random((40, len(st.params)))   # 40 x 1500 x n_sub: above the threshold
    assert 40 * 1500 * st.n_sub >= mmod._MIN_THREADED_STEPS
    old = mmod.kernel_threads()
    try:
        mmod.set_kernel_threads(1)
        y1 = st.simulate(W, r.op)
        mmod.set_kernel_threads(3)
        y3 = st.simulate(W, r.op)
    finally:
        mmod.set_kernel_threads(old)
    np.testing.assert_array_equal(y1, y3)
    assert np.isfinite(y1).any()
    with pytest.raises(ValueError, match="at least 1"):
        mmod.set_kernel_threads(0)


@pytest.mark.parametrize("effect, friction, seed, sticks", [
    ("slip_jump", 1.0, 6, True),       # S = 1.5 %, J = 1.9 % of the stroke
    ("none", 6.0, 5, True),            # the paper's valve, dead band 2 e_dead = 1.5 %
    ("none", 0.0, 5, False),           # frictionless valve
    ("none", 0.0, 6, False),
])
@pytest.mark.slow
def test_friction_verdict_on_known_valves(effect, friction, seed, sticks):
    case = make_case(effect, seed=seed, n=1200, friction=friction)
    res = diagnose(case.recording, plant="tank", candidates=(), effort="fast")
    s = res.to_dict()["stiction"]
    assert s["tested"] and s["present"] is sticks, s["explanation"]
    assert s["horch"]["verdict"] in ("stiction", "no stiction", "undetermined")  # a draining tank regulates itself
    if sticks:
        t = case.truth
        true_band = t["slip_jump.S"] if effect == "slip_jump" else 2 * t["valve.e_dead"]
        assert abs(s["band"] - true_band) < 0.3 * true_band
        assert s["band"] >= s["band_needed"] and s["delta_ic"] < 0
        assert s["explanation"].startswith("The valve sticks") and "that matters in this loop" in s["explanation"]
    else:
        assert s["band"] < 0.005 or s["delta_ic"] > -2.0
        assert s["explanation"].startswith("No")


def test_synthetic_friction_scale_is_checked():
    with pytest.raises(ValueError, match="friction must be a finite number"):
        make_case("none", seed=1, n=100, friction=-1.0)


@pytest.mark.slow
def test_auto_effort_follows_the_record_length():
    from valve_gym.diagnosis.diagnose import AUTO_THOROUGH_SAMPLES, resolve_effort

    assert resolve_effort("auto", AUTO_THOROUGH_SAMPLES) == "thorough"
    assert resolve_effort("auto", AUTO_THOROUGH_SAMPLES + 1) == "normal"
    assert resolve_effort("fast", 10) == "fast"
    with pytest.raises(ValueError, match="effort must be one of auto"):
        resolve_effort("quick", 100)
    res = diagnose(make_recording("none", seed=4, n=300), candidates=())
    assert res.to_dict()["settings"]["effort"] == "thorough"
    assert res.to_dict()["settings"]["effort_asked"] == "auto"


def test_parameter_uncertainty_covers_the_truth():
    import numpy as np

    from valve_gym.diagnosis.fit import fit_structure, parameter_uncertainty
    from valve_gym.diagnosis.model import DataScales, ModelStructure
    rng = np.random.default_rng(0)
    t = np.arange(800)
    u = 0.5 + 0.2 * np.sign(np.sin(2 * np.pi * t / 200))
    sc = DataScales.from_signals(u, np.linspace(0.0, 2.0, 800), 1.0)
    st = ModelStructure("first_order", "valve", (), sc, n_sub=2, friction=False)
    w_true = np.full(len(st.params), 0.5)
    y = st.simulate(w_true[None, :], u)[:, 0] + 0.01 * rng.normal(size=800)
    fit = fit_structure(st, u, y, rng=1, effort="fast", final_n_sub=False)
    pus = parameter_uncertainty(fit, u, y)
    truth = st.decode(w_true[None, :])
    assert {p.name for p in pus} <= set(truth)
    for p in pus:
        assert p.sd > 0 and abs(p.value - float(truth[p.name][0])) <= 4 * p.sd + 1e-9, p


# --------------------------------------------------------------------------- fast search
def _tank_fit(n=600, seed=12):
    """A whole-record tank fit of a synthetic recording: (structure, u, y, FitResult)."""
    from valve_gym.diagnosis.fit import fit_structure

    rec = make_case("none", seed=seed, n=n).recording
    sc = DataScales.from_signals(rec.op, rec.pv, rec.dt)
    st = ModelStructure("tank", "valve", (), sc)
    return st, rec.op, rec.pv, fit_structure(st, rec.op, rec.pv, rng=0, effort="fast")


def test_early_stop_ends_a_search_that_gains_nothing():
    """Warm-started at the exact optimum, the early-stopped evolution ends after its quiet generations."""
    from valve_gym.diagnosis.fit import fit_structure

    t = np.arange(600)
    u = 0.5 + 0.2 * np.sign(np.sin(2 * np.pi * t / 150))
    sc = DataScales.from_signals(u, np.linspace(0.0, 2.0, 600), 1.0)
    st = ModelStructure("first_order", "valve", (), sc, n_sub=2, friction=False)
    w = np.full((1, st.k), 0.5)
    y = st.simulate(w, u)[:, 0]
    full = fit_structure(st, u, y, seeds=w, rng=1, effort="normal", final_n_sub=False)
    fast = fit_structure(st, u, y, seeds=w, spread=np.full(st.k, 0.05), rng=1, effort="normal",
                         final_n_sub=False, early_stop=True)
    assert fast.n_evals < 0.6 * full.n_evals
    assert fast.cost <= 1e-20 and full.cost <= 1e-20
    np.testing.assert_allclose(fast.w, w[0], atol=1e-6)


def test_a_new_friction_law_gets_the_whole_search():
    """A warm start that leaves the friction coordinates unknown is searched as without a cloud."""
    from valve_gym.diagnosis.fit import fit_structure, transfer

    st, u, y, fit = _tank_fit(n=500, seed=3)
    st1 = st.with_effects(("slip_jump",))
    seeds, spread = transfer(fit, st1)
    assert spread[st1.index("S")] >= 1.0
    a = fit_structure(st1, u, y, seeds=seeds, spread=spread, rng=2, effort="fast", early_stop=True)
    b = fit_structure(st1, u, y, seeds=seeds, rng=2, effort="fast")
    assert a.n_evals == b.n_evals and np.array_equal(a.w, b.w)


def test_serial_blas_is_restored():
    from valve_gym.diagnosis.fit import _blas_libs, _SerialBlas

    libs = _blas_libs()
    if not libs:
        pytest.skip("numpy and scipy use a BLAS other than their own OpenBLAS here")
    before = [fn(2) for fn in libs]                        # set 2, remember what it was
    with _SerialBlas():
        assert [fn(1) for fn in libs] == [1] * len(libs)
    assert [fn(b) for fn, b in zip(libs, before)] == [2] * len(libs)


@pytest.mark.slow
def test_search_is_checked():
    rec = make_recording("none", seed=4, n=300)
    with pytest.raises(ValueError, match="search must be one of fast, full"):
        diagnose(rec, candidates=(), search="quick")
    assert diagnose(rec, candidates=(), effort="fast").to_dict()["settings"]["search"] == "full"
    assert diagnose(rec, candidates=(), effort="fast", search="fast").to_dict()["settings"]["search"] == "fast"


@pytest.mark.parametrize("plant, effects, horizon, saturation", [
    ("tank", ("leak", "slip_jump"), None, None),
    ("tank", ("dead_time",), 60, None),
    ("cascade", ("overflow",), None, (0.0, 10.0)),
    ("cascade", ("overflow", "sensor_curve"), None, (0.0, 10.0)),    # read outside the core: never stopped
    ("first_order", ("dead_time",), None, None),                     # an offset on the reading
    ("integrating", ("slip_jump",), None, None),                     # a fitted sign: -1 on some rows
])
def test_bounded_costs_are_the_costs_of_the_rows_that_can_win(plant, effects, horizon, saturation):
    """The fitter's early stop: a candidate whose error passes its bound costs inf (its true
    cost is above the bound); every other candidate's cost is bit for bit the unbounded one (the
    kernel's running sum of the squared errors, summed in the order numpy sums a column)."""
    from valve_gym.diagnosis.diagnose import _data_scales
    from valve_gym.diagnosis.fit import _Objective

    r = make_case("leak", seed=3, n=900).recording
    pv = r.pv if plant != "cascade" else 10.0 * (r.pv - r.pv.min()) / np.ptp(r.pv)
    rec = Recording(t=r.t, op=r.op, pv=pv, dt=r.dt)
    st = ModelStructure(plant, "valve", effects, _data_scales(rec, 600, saturation))
    rng = np.random.default_rng(2)
    W = rng.random((48, len(st.names)))
    k = len(st.names)
    obj = _Objective(st, r.op, pv, 600, np.arange(k), np.zeros(k), horizon)

    def summed(rows):
        """The costs summed from the simulated PV, as numpy sums them (the reference)."""
        E = st.simulate(rows, r.op[:600], reset=None if horizon is None else (pv, horizon)) - pv[:600, None]
        out = np.einsum("ij,ij->j", E, E)
        out[~np.isfinite(out)] = 1e300
        return out

    c = obj(W)
    np.testing.assert_array_equal(c, summed(W))       # no bound: every row's whole cost
    bound = np.quantile(c, 0.4) * rng.uniform(0.5, 1.5, len(c))
    bound[:3] = np.inf
    Y = st.simulate(W, r.op[:600], reset=None if horizon is None else (pv, horizon))
    cb = obj(W, bound=bound)
    kept = np.isfinite(cb)
    np.testing.assert_array_equal(cb[kept], c[kept])
    # the bounded runs write into a scratch buffer: an earlier simulation is not touched
    np.testing.assert_array_equal(Y, st.simulate(W, r.op[:600], reset=None if horizon is None else (pv, horizon)))
    assert np.all(c[~kept] > bound[~kept])
    assert kept[:3].all()
    # a batch of one row, and of two (numpy sums a single column in another order than a batch)
    for rows in (W[3:4], W[3:5]):
        np.testing.assert_array_equal(obj(rows), summed(rows))
        np.testing.assert_array_equal(obj(rows, bound=np.full(len(rows), 1e300)), summed(rows))
    if "sensor_curve" in effects:
        assert kept.all()
    else:
        assert (~kept).sum() >= 0.8 * (c > bound).sum() > 0


def test_decode_is_each_parameter_value_and_checks_the_shape():
    """The vectorised decoding gives each FreeParam.value's numbers exactly, and refuses a wrong width."""
    from valve_gym.diagnosis.diagnose import _data_scales

    r = make_case("leak", seed=3, n=600).recording
    rng = np.random.default_rng(5)
    for plant, effects in (("tank", ("leak", "slip_jump")), ("first_order", ("dead_time",)),
                           ("cascade", ("overflow",))):
        st = ModelStructure(plant, "valve", effects, _data_scales(r, 400, None))
        W = rng.random((9, len(st.names))) * 1.4 - 0.2          # outside 0..1 too: clipped
        got = st.decode(W)
        for i, p in enumerate(st.params):
            np.testing.assert_array_equal(got[p.name], p.value(W[:, i]))
        with pytest.raises(ValueError, match="one column per free parameter"):
            st.decode(W[:, :1])


def test_the_report_states_the_effective_samples_the_criterion_counts(overflow_result):
    from valve_gym.diagnosis.fit import effective_n
    from valve_gym.diagnosis.report import render_markdown

    d = json.loads(overflow_result.to_json())
    sel = overflow_result.selection
    assert d["holdout"]["n_eff"] == effective_n(sel.base.residual[:sel.base.n_fit])
    assert 5 <= d["holdout"]["n_eff"] <= d["holdout"]["n_fit"]
    md = render_markdown(overflow_result, {})
    h = d["holdout"]
    assert f"The criterion counts {h['n_eff']:.0f} effective samples in the {h['n_fit']} fitted" in md


# --------------------------------------------------------------------------- bad or degenerate input
# a clear error, never a crash or a silent answer
def _flat_pv_record(n=200):
    """An OP that wanders while the PV sits still for most of the record (a frozen transmitter)."""
    rng = np.random.default_rng(0)
    op = np.clip(0.5 + np.cumsum(rng.normal(0, 0.003, n)), 0, 1)
    pv = np.where(np.arange(n) < 180, 0.8, 0.7)
    return Recording(np.arange(float(n)), op, pv, name="flat")


@pytest.mark.parametrize("op_lag", ["auto", 0])
def test_a_pv_that_does_not_move_over_the_fitted_part_is_refused(op_lag):
    # before: op_lag 'auto' crashed with ZeroDivisionError (both pairings fit exactly), and op_lag 0 called
    # the valve sticky with a band of 0
    with pytest.raises(ValueError, match=r"the PV takes only 1 value\(s\) \(0.8\) over the fitted part "
                                         r"\(samples 0-139 of 200\).*use a stretch where the PV moves"):
        diagnose(_flat_pv_record(), plant="first_order", candidates=(), effort="fast", op_lag=op_lag)


def test_the_pairing_test_has_no_underflow_for_a_pv_in_tiny_units():
    from valve_gym.diagnosis.diagnose import _choose_op_lag
    from valve_gym.diagnosis.fit import effective_n
    from valve_gym.diagnosis.select import SelectionRule

    class Fit:                                       # the two base fits' errors, as the test reads them
        def __init__(self, rmse):
            self.rmse, self.residual, self.n_fit = rmse, np.random.default_rng(0).normal(0, rmse, 300), 300

    rec = make_recording("none", seed=1, n=300)
    reaction = {"op_lag": None}
    lag, test = _choose_op_lag({0: (rec, Fit(2e-200), 300), 1: (rec, Fit(1e-200), 300)}, SelectionRule(),
                               "auto", rec, reaction)
    assert np.isfinite(test["delta_ic"]) and test["delta_ic"] < 0          # ln(1/4) n_eff: finite, negative
    assert lag == 1
    assert test["n_eff"] == effective_n(Fit(1.0).residual)                   # the units do not matter


def test_too_few_samples_after_the_holdout_says_what_to_do():
    rec = make_recording("none", seed=1, n=300)
    short = Recording(rec.t[:55], rec.op[:55], rec.pv[:55], name="fifty-five")
    with pytest.raises(ValueError, match=r"only 39 samples to fit after the holdout of 0.3; need >= 40: lower the "
                                         r"holdout \(--holdout 0.1"):
        diagnose(short, plant="tank", candidates=())


@pytest.mark.slow
def test_candidates_may_be_a_string_and_bad_seed_or_sensor_range_are_named():
    rec = make_recording("overflow", seed=32, n=300)
    res = diagnose(rec, plant="tank", candidates="overflow", effort="fast")        # one effect, not 'o','v',...
    assert res.settings["candidates"] == ["overflow"] or tuple(res.settings["candidates"]) == ("overflow",)
    with pytest.raises(ValueError, match="unknown effect 'lek'"):
        diagnose(rec, plant="tank", candidates="overflow, lek")
    with pytest.raises(ValueError, match="seed must be a whole number >= 0, got -1"):
        diagnose(rec, plant="tank", candidates=(), seed=-1)
    with pytest.raises(ValueError, match=r"saturation \(lo, hi\) must be finite with lo < hi"):
        diagnose(rec, plant="tank", candidates=(), saturation=(2.0, 1.0))
    with pytest.raises(ValueError, match="saturation must be 'auto', None or a pair"):
        diagnose(rec, plant="tank", candidates=(), saturation="0-2")
