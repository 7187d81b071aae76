"""The logistic combination, the size combination and the textbook loop simulator."""
import numpy as np
import pytest

from valve_gym.diagnosis.stiction import FEATURES, LogisticModel, fit_logistic
from valve_gym.diagnosis.stiction.combine import combine_sizes, verdict_of
from valve_gym.diagnosis.stiction.hammerstein import SizeEstimate
from valve_gym.diagnosis.stiction.loops import LoopSpec, _TwoParam, simulate_loop


def test_logistic_separates_and_is_calibrated_on_balanced_noise():
    rng = np.random.default_rng(0)
    n = 400
    y = (rng.random(n) < 0.3).astype(float)
    X = rng.normal(size=(n, len(FEATURES)))
    X[:, 0] += 2.0 * y                                     # one informative feature
    m = fit_logistic(X, y)
    p = m.probability(X)
    assert p[y == 1].mean() > 0.7 and p[y == 0].mean() < 0.3
    assert abs(m.coef[0]) > 3 * max(abs(c) for c in m.coef[1:])
    assert LogisticModel.from_dict(m.to_dict()) == m
    with pytest.raises(ValueError, match="both classes"):
        fit_logistic(X, np.zeros(n))
    with pytest.raises(ValueError, match="do not match"):
        LogisticModel.from_dict({**m.to_dict(), "names": ["a"]})


def test_verdict_bands():
    assert verdict_of(0.9) == "stiction" and verdict_of(0.1) == "no stiction"
    assert verdict_of(0.55) == "undecided"


def test_combine_sizes_primary_method_and_agreement():
    fit = SizeEstimate("hammerstein", 0.035, 0.03, 0.045, 0.01, 0.005, 0.015)
    ell = SizeEstimate("ellipse", 0.03, 0.02, 0.04, np.nan, np.nan, np.nan)
    s, agree = combine_sizes([fit, ell])
    assert agree is True and (s.S, s.S_lo, s.S_hi, s.J) == (0.035, 0.03, 0.045, 0.01)
    far = SizeEstimate("ellipse", 0.08, 0.07, 0.09, np.nan, np.nan, np.nan)
    assert combine_sizes([fit, far])[1] is False
    assert combine_sizes([ell])[1] is None
    assert np.isnan(combine_sizes([])[0].S)


def test_choudhury_valve_sticks_for_S_then_jumps_J():
    v = _TwoParam(S=0.04, J=0.01, kano=False, u0=0.5)
    up = [v.step(u) for u in np.linspace(0.5, 0.6, 101)]      # first motion: needs S, then moves
    assert up[30] == 0.5 and up[-1] == pytest.approx(0.6 - 0.015)
    down = [v.step(u) for u in np.linspace(0.6, 0.55, 51)]    # reversal: stuck for S ...
    assert down[35] == up[-1]
    moved = np.nonzero(np.diff(down))[0]
    jump = down[moved[0] + 1] - down[moved[0]]
    assert jump == pytest.approx(-0.01, abs=1.5e-3)            # ... then slips by J


def test_integrating_loop_limit_cycle_matches_textbook_amplitudes():
    # DOMAIN: integrating loop with a sticky valve cycles with OP p-p ~ S, PV amplitude ~ S/(2 Kc)
    spec = LoopSpec(process="integrating", valve="choudhury", S=0.04, J=0.01, k_i=0.1, Kc=2.0, Ti=20.0,
                    Ts=0.1, theta=0.0, noise=0.0, tau_v=0.01, n=20000, sp_step=0.05)
    rec = simulate_loop(spec, seed=0)
    half = rec.op[len(rec.op) // 2:]
    assert np.ptp(half) == pytest.approx(0.04, rel=0.15)
    assert 0.5 * np.ptp(rec.pv[len(rec.pv) // 2:]) == pytest.approx(0.04 / (2 * 2.0), rel=0.15)


def test_logistic_feature_subset_ignores_the_rest():
    rng = np.random.default_rng(1)
    n = 300
    y = (rng.random(n) < 0.5).astype(float)
    X = rng.normal(size=(n, len(FEATURES)))
    X[:, 1] += 3.0 * y                                     # informative, but not in the subset
    X[:, 0] += 1.0 * y
    m = fit_logistic(X, y, use=(FEATURES[0],))
    assert m.coef[0] > 0 and all(c == 0.0 for c in m.coef[1:])
    assert (m.mean[1], m.scale[1]) == (0.0, 1.0)
    X2 = X.copy()
    X2[:, 1:] = 99.0                                       # the ignored features do not move p
    np.testing.assert_allclose(m.probability(X2), m.probability(X))
    with pytest.raises(ValueError, match="unknown stiction features"):
        fit_logistic(X, y, use=("nope",))


def _tank(shape, sp_step=0.3, sp_moves=0.0):
    return LoopSpec(process="tank", valve="linear", S=0.0, J=0.0, area=1.0, q_max=0.02, c_out=0.01, Kc=2.0,
                    Ti=200.0, Ts=2.0, theta=0.0, noise=0.0, tau_v=0.2, n=600, sp_step=sp_step,
                    sp_moves=sp_moves, shape=shape)


def test_tank_shapes_change_the_dynamics_not_the_steady_state():
    from valve_gym.diagnosis.stiction.loops import TANK_SHAPES, _area
    y0 = 1.0
    assert _area(_tank("cone"), 0.5, y0) == pytest.approx(0.25)        # A ~ y^2
    assert _area(_tank("sphere"), 0.5, y0) == pytest.approx(0.75)      # A ~ y (2 y0 - y)
    assert _area(_tank("horizontal_cylinder"), 0.5, y0) == pytest.approx(0.75 ** 0.5)
    assert _area(_tank("cylinder"), 0.5, y0) == 1.0
    for s in TANK_SHAPES:                                   # every tank settles at the new set point
        r = simulate_loop(_tank(s), seed=0)
        assert r.sp is not None and abs(r.pv[-1] - r.sp[-1]) < 0.02 * r.sp[-1]
    # set-point moves of +-0.3 around y0 = 1: a cone (area ~ y^2) responds differently from a cylinder
    moves = {s: simulate_loop(_tank(s, 0.0, 0.3), seed=0).pv for s in ("cone", "cylinder")}
    assert np.max(np.abs(moves["cone"] - moves["cylinder"])) > 0.02
    with pytest.raises(ValueError, match="tank shape"):
        simulate_loop(_tank("pyramid"))


def test_plant_effects_of_the_textbook_simulator():
    from dataclasses import replace

    from valve_gym.diagnosis.stiction.loops import _flow_fraction
    base = _tank("cylinder", 0.0, 0.3)
    assert _flow_fraction(replace(base, characteristic="equal_percentage", rangeability=30.0), 1.0) == 1.0
    assert _flow_fraction(replace(base, characteristic="equal_percentage", rangeability=30.0), 0.5) == \
        pytest.approx(30.0 ** -0.5)
    assert _flow_fraction(replace(base, characteristic="quick_opening"), 0.25) == pytest.approx(0.5)
    ref = simulate_loop(base, seed=0)
    # overflow: the level never rises above the rim, so the PV stays below the highest set points
    top = simulate_loop(replace(base, level_max=1.2), seed=0)
    assert top.pv.max() <= 1.2 + 1e-12 < ref.pv.max()
    # a sensor lag delays the measured response to the set-point steps
    lag = simulate_loop(replace(base, sensor_tau=30.0), seed=0)
    k = int(np.flatnonzero(np.diff(ref.sp))[0]) + 1
    assert abs(lag.pv[k + 5] - lag.pv[k - 1]) < abs(ref.pv[k + 5] - ref.pv[k - 1])
    # equal percentage: at the starting opening (50 %) the flow is 30^-0.5 of the full flow, not half,
    # and the Torricelli level goes with the square of the flow
    eq = simulate_loop(replace(base, characteristic="equal_percentage"), seed=0)
    assert eq.sp is not None and ref.sp is not None
    assert eq.sp[0] == pytest.approx(ref.sp[0] * (30.0 ** -0.5 / 0.5) ** 2)
    with pytest.raises(ValueError, match="characteristic"):
        simulate_loop(replace(base, characteristic="butterfly"))
    with pytest.raises(ValueError, match="sensor_tau"):
        simulate_loop(replace(base, sensor_tau=0.01))
