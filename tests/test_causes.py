"""The cause of an oscillation (valve_gym.diagnosis.causes) and the verdict's invariance to units."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from valve_gym.diagnosis.causes import (
    CAUSES,
    OscillationCause,
    estimate_pi,
    gain_margin,
    oscillation_cause,
    shared_periods,
)


def test_gain_margin_of_a_fopdt_loop_matches_the_analytic_value():
    # K=1, T=50 s, theta 8.5 s + 1.5 samples = 10 s, P control Kc=1: -atan(50 w) - 10 w = -pi at w ~ 0.168
    gm, p180 = gain_margin({"process.K": 1.0, "process.T": 50.0, "dead_time.theta": 8.5}, "first_order",
                           1.0, math.inf, 1.0)
    w = 2 * math.pi / p180
    assert abs(math.atan(50 * w) + 10 * w - math.pi) < 1e-2
    assert gm == pytest.approx(math.sqrt(1 + (50 * w) ** 2), rel=1e-2)
    assert gain_margin({"process.K": -1.0, "process.T": 50.0}, "first_order", 1.0, math.inf, 1.0)[0] > 1
    assert math.isnan(gain_margin({}, "tank", 1.0, 10.0, 1.0)[0])


def test_estimate_pi_reads_the_law_that_made_the_output():
    rng = np.random.default_rng(0)
    e = np.cumsum(rng.standard_normal(800)) * 0.01
    pv = 5.0 - e
    Kc, Ti, dt = 0.8, 40.0, 2.0
    op = np.zeros(800)
    op[0] = 0.5
    for k in range(1, 800):
        op[k] = op[k - 1] + Kc * ((e[k] - e[k - 1]) + dt / Ti * e[k])
    got = estimate_pi(op, pv, np.full(800, 5.0), dt)
    assert got["Kc"] == pytest.approx(Kc, rel=1e-6) and got["Ti"] == pytest.approx(Ti, rel=1e-6)
    assert got["r2"] > 0.999


def _cycle(n=1200, period=60.0, seed=0):
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    return np.sin(2 * np.pi * k / period), rng


def test_quantised_pv_is_a_sensor_cause():
    s, rng = _cycle()
    pv = np.round(0.6 * s + 0.3) * 0.5 + 20.0                 # two or three levels 0.5 apart
    op = 0.5 - 0.05 * np.cumsum(pv - pv.mean()) / 60 + 0.001 * rng.standard_normal(len(s))
    c = oscillation_cause(op, pv, 1.0, sp=np.full(len(s), 20.2), p_stiction=0.5)
    assert c.oscillating and c.cause == "sensor" and c.probabilities["sensor"] > 0.5
    assert any("levels" in e.statement for e in c.evidence)


def test_output_at_its_limit_is_saturation_and_set_point_oscillation_is_a_disturbance():
    s, rng = _cycle()
    op = np.clip(0.8 + 0.4 * s, 0.0, 1.0)
    pv = 3.0 * s + 0.05 * rng.standard_normal(len(s))
    c = oscillation_cause(op, pv, 1.0, p_stiction=0.3)
    assert c.cause == "saturation" and "sits at its maximum" in c.sentence()
    sp = 2.0 * np.sin(2 * np.pi * np.arange(len(s)) / 60.0 + 0.3)
    d = oscillation_cause(0.5 + 0.1 * s, pv, 1.0, sp=sp, p_stiction=0.3)
    assert d.cause == "disturbance" and "set point oscillates" in d.sentence()
    assert "upstream" in d.action()


def test_a_quiet_loop_has_no_cause():
    rng = np.random.default_rng(1)
    c = oscillation_cause(0.5 + 0.01 * rng.standard_normal(600), rng.standard_normal(600), 1.0)
    assert not c.oscillating and c.cause == "none" and c.to_dict()["probabilities"] == {}


def test_shared_periods_move_a_loop_towards_a_disturbance():
    scores = {c: 0.0 for c in CAUSES}
    base = OscillationCause(True, 100.0, {c: 0.2 for c in CAUSES}, "stiction", (), scores=scores)
    moved = base.with_shared_period(["FIC2", "LIC3"])
    assert moved.cause == "disturbance" and moved.probabilities["disturbance"] > 0.5
    assert moved.shared_with == ("FIC2", "LIC3") and "Thornhill" in moved.evidence[-1].statement
    assert shared_periods({"a": 100.0, "b": 108.0, "c": 300.0, "d": math.nan}) == {"a": ("b",), "b": ("a",),
                                                                                   "c": ()}


def test_plantwide_keeps_the_source_and_moves_the_others():
    import json

    from valve_gym.fleet.plantwide import apply_shared_periods
    from valve_gym.fleet.result import LoopResult

    def row(name, p_stick, period):
        sc = {c: 0.0 for c in CAUSES}
        sc["stiction"] = math.log(p_stick / (1 - p_stick))
        return LoopResult(loop=name, status="ok", message="", oscillating=True, period_s=period, amplitude_op=0.02,
                          cause="stiction" if p_stick > 0.5 else "tuning", cause_scores=json.dumps(sc),
                          p_valve=p_stick, action="x")

    out = apply_shared_periods([row("SRC", 0.9, 100.0), row("RCV", 0.6, 104.0), row("FAR", 0.6, 400.0)])
    src, rcv, far = out
    assert src.cause == "stiction" and "likely source" in src.cause_evidence
    assert rcv.cause == "disturbance" and "likely source: SRC" in rcv.action
    assert far == row("FAR", 0.6, 400.0)


@pytest.mark.slow
def test_stiction_verdict_does_not_depend_on_the_units(tmp_path):
    """The same sticky loop with its PV x1000, /1000 and offset, and its OP in percent, gets the same verdict."""
    from valve_gym.diagnosis import diagnose, load_recording
    from valve_gym.diagnosis.synthetic import write_csv
    from valve_gym.fleet.simulate import simulate_loop

    rec = replace(simulate_loop("sticky", seed=5, n=600).recording, name="PIC_sticky")
    results = {}
    for label, a, b in (("as is", 1.0, 0.0), ("x1000", 1000.0, 0.0), ("/1000", 1e-3, 0.0), ("offset", 1.0, -350.0)):
        r = replace(rec, pv=a * rec.pv + b, sp=None if rec.sp is None else a * rec.sp + b)
        results[label] = diagnose(r, candidates=(), effort="fast")
    p = tmp_path / "PIC_sticky.csv"
    write_csv(rec, p, percent=True)                          # OP written in percent, read without --op-range
    pct = load_recording(p)
    assert pct.op_range == (0.0, 100.0)
    results["percent"] = diagnose(pct, candidates=(), effort="fast")
    ref = results["as is"]
    assert ref.stiction["probability"] > 0.5                  # the sticky valve is seen at all
    for label, res in results.items():
        assert res.stiction["present"] == ref.stiction["present"], label
        assert res.stiction["verdict"] == ref.stiction["verdict"], label
        assert res.stiction["probability"] == pytest.approx(ref.stiction["probability"], abs=0.1), label
        assert (res.cause.cause if res.cause else None) == (ref.cause.cause if ref.cause else None), label
