"""The stem test: stiction read from a recorded valve position against the controller output."""
import numpy as np
import pytest

from valve_gym.diagnosis import Recording, diagnose, load_recording
from valve_gym.diagnosis.stiction.loops import LoopSpec, simulate_loop
from valve_gym.diagnosis.stiction.stem import stem_evidence, stem_size


def _output(T=2400, seed=1):
    """An output like a PI's at constant set point: a slow random walk with noise, 0..1."""
    rng = np.random.default_rng(seed)
    return np.clip(0.5 + np.cumsum(rng.normal(0, 0.002, T)) + rng.normal(0, 0.003, T), 0, 1), rng


def _independent_choudhury(u, S, J):
    """Choudhury's law written out here (stick point kept while stuck), as a check on the package's."""
    x, us, stuck, d = u[0], u[0], True, 0.0
    out = np.empty(len(u))
    out[0] = x
    for k in range(1, len(u)):
        du = u[k] - u[k - 1]
        s = np.sign(du)
        if not stuck and (s == 0 or s != d):
            stuck, us = True, u[k - 1]
        if stuck:
            dev = u[k] - us
            need = J if (d != 0 and (dev > 0) == (d > 0)) else S
            if abs(dev) > need:
                d, stuck = (1.0 if dev > 0 else -1.0), False
        if not stuck:
            x = u[k] - d * (S - J) / 2
        out[k] = x
    return out


def test_sticky_stem_is_found_and_sized():
    op, rng = _output()
    x = _independent_choudhury(op, 0.03, 0.015)
    mv = 0.01 + 0.97 * x + rng.normal(0, 0.001, len(op))       # a transmitter's offset, span and noise
    e = stem_evidence(op, mv, 1.0, band_needed=0.01)
    d = e.details
    assert e.applicable and e.verdict == "stiction"
    assert d["S_lo"] <= 0.03 <= d["S_hi"] and abs(d["S"] / 0.03 - 1) < 0.15
    assert d["J_lo"] <= 0.015 <= d["J_hi"]
    assert d["delta_ic"] < -10 and 0.9 < d["span"] < 1.05
    s = stem_size(e)
    assert s.method == "stem" and s.S == d["S"] and s.S_lo <= s.S <= s.S_hi


def test_healthy_stem_is_cleared_and_a_small_band_does_not_matter():
    op, rng = _output(seed=2)
    lagged = np.empty_like(op)                       # a positioner lag of one sample, no friction
    lagged[0] = op[0]
    for k in range(1, len(op)):
        lagged[k] = 0.37 * lagged[k - 1] + 0.63 * op[k]
    e = stem_evidence(op, 0.02 + lagged + rng.normal(0, 0.001, len(op)), 1.0)
    assert e.verdict == "no stiction" and e.details["S"] < 0.01
    small = _independent_choudhury(op, 0.004, 0.0)   # a healthy positioner's dead band
    e = stem_evidence(op, small + rng.normal(0, 0.0005, len(op)), 1.0, band_needed=0.01)
    assert e.verdict == "no stiction" and "below the 1 %" in e.reason


def test_stem_refuses_what_it_cannot_read():
    op, rng = _output(T=600)
    assert not stem_evidence(op, None).applicable
    e = stem_evidence(op, op.copy())
    assert not e.applicable and "readback" in e.reason
    e = stem_evidence(op, np.full(len(op), 0.4) + rng.normal(0, 1e-4, len(op)))
    assert e.verdict == "undetermined" and "seized valve or a frozen position signal" in e.reason
    e = stem_evidence(op, rng.random(len(op)))
    assert e.verdict == "undetermined" and "does not follow the output" in e.reason
    assert stem_size(e).method == "none"
    with pytest.raises(ValueError, match="same shape"):
        stem_evidence(op, op[:-1])


def test_kano_valve_of_the_independent_simulator():
    """A Kano valve of the textbook simulator (its own code, not the package's law), no limit cycle needed."""
    spec = LoopSpec(process="tank", valve="kano", S=0.03, J=0.02, Kc=3.0, Ti=40.0, Ts=1.0, noise=0.002,
                    tau_v=0.3, n=1500, load=0.004, sp_moves=0.3)
    rec = simulate_loop(spec, seed=4, stem=True)
    assert rec.mv is not None and rec.columns["mv"] == "mv"
    e = stem_evidence(rec.op, rec.mv, 1.0)
    assert e.verdict == "stiction" and e.details["S_lo"] <= 0.03 <= e.details["S_hi"]
    same = simulate_loop(spec, seed=4)               # the stem is recorded without changing the loop
    assert same.mv is None and np.array_equal(same.op, rec.op) and np.array_equal(same.pv, rec.pv)


@pytest.fixture(scope="module")
def sticky_loop():
    spec = LoopSpec(process="integrating", valve="kano", S=0.04, J=0.02, k_i=0.02, Kc=4.0, Ti=60.0, Ts=1.0,
                    theta=2.0, noise=0.0003, tau_v=0.2, n=900, sp_step=0.02)
    return simulate_loop(spec, seed=3, stem=True)


def test_diagnosis_reads_the_stem_when_recorded(sticky_loop, tmp_path):
    s = diagnose(sticky_loop, plant="integrating", candidates=(), effort="fast").stiction
    assert s["verdict_source"] == "stem" and s["present"] is True
    stem = next(e for e in s["evidence"] if e["method"] == "stem")
    assert stem["verdict"] == "stiction"
    assert s["S"] == stem["details"]["S"] and s["sizes"][0]["method"] == "stem"
    assert s["S_interval"][0] <= 0.04 <= s["S_interval"][1]
    assert "Recorded valve position" in s["explanation"] and "stem" not in s["features"]
    # through the loader: a CSV with a position column in percent
    path = tmp_path / "loop.csv"
    r = sticky_loop
    np.savetxt(path, np.c_[r.t, 100 * r.op, r.pv, 100 * r.mv], delimiter=",", header="t,OP,PV,valve_position",
               comments="")
    rec = load_recording(str(path), op_range=(0, 100))
    assert rec.mv is not None and np.allclose(rec.mv, r.mv)
    s2 = diagnose(rec, plant="integrating", candidates=(), effort="fast").stiction
    assert s2["verdict_source"] == "stem" and s2["present"] is True


def test_diagnosis_without_a_stem_is_unchanged(sticky_loop):
    rec = Recording(t=sticky_loop.t, op=sticky_loop.op, pv=sticky_loop.pv, sp=sticky_loop.sp,
                    dt=sticky_loop.dt, name="no_stem")
    s = diagnose(rec, plant="integrating", candidates=(), effort="fast").stiction
    assert s["verdict_source"] == "methods"
    assert all(e["method"] != "stem" for e in s["evidence"]) and "Recorded valve position" not in s["explanation"]


def test_cli_reads_a_position_in_its_own_range(sticky_loop, tmp_path, capsys):
    """``--mv-range``: a position logged 0..10 V beside an output in percent."""
    from valve_gym.diagnosis.cli import main

    r = sticky_loop
    path = tmp_path / "LIC7.csv"
    np.savetxt(path, np.c_[r.t, 100 * r.op, r.pv, 10 * r.mv], delimiter=",", header="t,op,pv,pos", comments="")
    js = tmp_path / "out.json"
    rc = main([str(path), "--op-range", "0,100", "--mv-range", "0,10", "--plant", "integrating", "--effects",
               "none", "--effort", "fast", "--jobs", "1", "--json", str(js), "--quiet"])
    assert rc == 0, capsys.readouterr().err
    import json
    s = json.loads(js.read_text())["stiction"]
    assert s["verdict_source"] == "stem" and s["present"] is True
    # without --mv-range the position is read like the output (0..100): a tenth of the stroke, refused
    rc = main([str(path), "--op-range", "0,100", "--plant", "integrating", "--effects", "none", "--effort",
               "fast", "--jobs", "1", "--json", str(js), "--quiet"])
    assert rc == 0
    s = json.loads(js.read_text())["stiction"]
    stem = next(e for e in s["evidence"] if e["method"] == "stem")
    assert s["verdict_source"] == "methods" and stem["verdict"] == "undetermined" and "span" in stem["reason"]


def test_fleet_sends_a_loop_whose_stem_sticks_to_the_full_diagnosis(sticky_loop):
    from valve_gym.fleet.analyse import position_sticks

    assert position_sticks(sticky_loop) is True
    healthy = simulate_loop(LoopSpec(process="integrating", valve="linear", k_i=0.02, Kc=4.0, Ti=60.0, Ts=1.0,
                                     noise=0.0003, tau_v=0.2, n=900, sp_step=0.02, load=0.005), seed=5, stem=True)
    assert position_sticks(healthy) is False
    assert position_sticks(Recording(t=sticky_loop.t, op=sticky_loop.op, pv=sticky_loop.pv, dt=1.0)) is False


def test_stem_size_comes_first_and_the_others_check_it(sticky_loop):
    from valve_gym.diagnosis.stiction import assess_stiction

    a = assess_stiction(sticky_loop.op, sticky_loop.pv, 1.0, "integrating", mv=sticky_loop.mv)
    stem = next(e for e in a.evidence if e.method == "stem")
    assert stem.verdict == "stiction" and a.sizes[0].method == "stem" and a.S == stem.details["S"]
    others = [s for s in a.sizes[1:] if np.isfinite(s.S)]
    expect = None if not others else all(s.S_lo <= a.S_interval[1] and a.S_interval[0] <= s.S_hi for s in others)
    assert a.sizes_agree == expect


def test_a_position_that_never_moves_seized_or_frozen():
    """The process model tells a seized valve from a frozen position signal (verdict.frozen_position)."""
    from dataclasses import replace

    from valve_gym.diagnosis.explain import explain_friction
    from valve_gym.diagnosis.stiction import Evidence, StictionAssessment
    from valve_gym.diagnosis.stiction.hammerstein import SEIZED_TRAVEL
    from valve_gym.diagnosis.verdict import FreeRunTest, decide_friction, frozen_position

    nan = float("nan")
    frozen = Evidence("stem", "", False, nan, 0.0, "undetermined", "", "", {"frozen": 1.0})
    a = StictionAssessment(0.2, "no stiction", nan, nan, (nan, nan), (nan, nan), None, [], [frozen])
    t = FreeRunTest(parameters={"model": "slip_jump", "S": 0.30, "J": 0.0, "band": 0.30}, delta_ic=5.0,
                    significant=False, band=0.30, slips=0, band_needed=0.01, op_working_range=0.40, n_eff=100.0,
                    frictionless_model="tank + valve", frictionless_rmse=1.0, friction_rmse=1.0, compared={})
    v = decide_friction(t, None, a, None)
    assert frozen_position(frozen, t) == "seized" and v.present is True and v.verdict_source == "stem+model"
    assert "the valve is seized" in explain_friction(v)
    t = replace(t, band=0.02)
    v = decide_friction(t, None, a, None)
    assert frozen_position(frozen, t) == "frozen_signal" and v.present is False and v.verdict_source == "methods"
    assert "transmitter" in explain_friction(v)
    quiet = 0.5 * SEIZED_TRAVEL          # too little travel to tell: nothing concluded, even with a wide band
    t = replace(t, band=quiet, op_working_range=quiet)
    v = decide_friction(t, None, a, None)
    assert frozen_position(frozen, t) == "short_travel" and v.present is False and "too little" in explain_friction(v)
    moving = Evidence("stem", "", True, 0.03, 1.0, "stiction", "", "", {"S": 0.03})
    assert frozen_position(moving, t) is None and frozen_position(None, t) is None


@pytest.mark.slow
def test_report_shows_the_stem(sticky_loop, tmp_path):
    from valve_gym.diagnosis.report import write_report

    res = diagnose(sticky_loop, plant="integrating", candidates=(), effort="fast")
    paths = write_report(res, tmp_path / "rep")
    assert any(p.endswith("stem.png") for p in paths)
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "stem.png" in md and "recorded valve position" in md
    plain = Recording(t=sticky_loop.t, op=sticky_loop.op, pv=sticky_loop.pv, dt=1.0, name="plain")
    paths = write_report(diagnose(plain, plant="integrating", candidates=(), effort="fast"), tmp_path / "p2")
    assert not any(p.endswith("stem.png") for p in paths)


def test_a_held_position_is_flagged():
    """A position stored only when it moves by 1 % (a historian's compression with hold) reads as sticking."""
    op, rng = _output(seed=3)
    held = np.empty_like(op)
    held[0] = op[0]
    for k in range(1, len(op)):
        held[k] = op[k] if abs(op[k] - held[k - 1]) > 0.012 else held[k - 1]
    e = stem_evidence(op, held, 1.0)
    assert e.details["repeats"] > 0.5
    if e.verdict == "stiction":
        assert "compression" in e.reason
    moving = stem_evidence(op, op + rng.normal(0, 1e-3, len(op)), 1.0)
    assert moving.details["repeats"] < 0.01 and "compression" not in moving.reason


def test_healthy_valves_that_are_slow_or_characterised_are_not_called():
    """A slew-rate-limited actuator and a position read through a curve are not stiction."""
    rng = np.random.default_rng(0)
    T = 2400
    op = 0.5 + np.cumsum(rng.normal(0, 0.002, T)) + rng.normal(0, 0.003, T)
    op = np.clip(op + np.repeat(rng.choice([-0.05, 0.0, 0.05], T // 200), 200), 0, 1)
    slow = np.empty(T)
    slow[0] = op[0]
    for k in range(1, T):
        slow[k] = slow[k - 1] + np.clip(op[k] - slow[k - 1], -0.002, 0.002)     # 0.2 % of stroke per sample
    for mv in (slow, op ** 1.5, 30.0 ** (op - 1.0)):
        e = stem_evidence(op, np.clip(mv + rng.normal(0, 1e-3, T), 0, 1), 1.0)
        assert e.verdict == "no stiction", e.reason
