"""The one PI law: valve_gym.control.pi_scan1 is the scan of the DCS blocks and of the regulation block."""
from __future__ import annotations

import numpy as np

from valve_gym.agents.controllers.pi import PIBlock
from valve_gym.control import integral_gain, pi_scan, pi_scan1, pi_track
from valve_gym.envs.regulation import BlockLaw, BlockSettings


def test_compiled_scan_equals_the_numpy_block_bit_for_bit():
    rng = np.random.default_rng(3)
    n = 400
    blk = PIBlock(Kc=1.7, Ti=25.0, scan_s=0.5)
    state = blk.initial_state(np.ones(n), rng.uniform(0.8, 1.2, n), rng.uniform(0, 1, n))
    ki = integral_gain(1.7, 25.0, 0.5)
    for _ in range(30):
        e = rng.normal(0.0, 0.3, n)                 # large errors: the limits act often
        bias = rng.normal(0.0, 0.2, n)
        integrate = rng.random(n) < 0.8
        scan = blk.propose(state, e, np.zeros(n), integrate)  # type: ignore[arg-type]  # (n,) gates are allowed
        new, op = blk.finish(scan, bias)
        for i in range(n):
            u, I_new = pi_scan1(state.integral[i], e[i], 1.7, ki, float(integrate[i]), bias[i], 0.0, 1.0, True)
            assert (u, I_new) == (op[i], new.integral[i])
        state = new
    assert np.any(op == 1.0) and np.any(op == 0.0)


def test_numpy_faces_are_the_compiled_formulas():
    p, integral, v = pi_scan(np.array([0.5]), np.array([0.1]), 2.0, 10.0, 1.0)
    assert integral[0] == 0.5 + integral_gain(2.0, 10.0, 1.0) * 0.1 and v[0] == p[0] + integral[0]
    assert pi_track(1.0, 0.25, 0.5)[()] == 1.0 - 0.25 - 0.5


def test_regulation_block_runs_the_forward_form_of_the_same_scan():
    s = BlockSettings()
    n = 64
    rng = np.random.default_rng(5)
    law = BlockLaw(s, n)
    sp, pv, op = np.ones(n), rng.uniform(0.9, 1.1, n), rng.uniform(0, 1, n)
    law.reset(sp, pv, op)
    integ = law.state_arrays()["I"]
    ki = integral_gain(s.Kc, s.Ti, s.scan_s)
    for k in range(40):
        pv = rng.uniform(0.7, 1.3, n)
        law.observe(sp, pv)
        a = rng.uniform(-1, 1, (n, 2))
        u = law.act(a)
        g = s.g_min + (1.0 - s.g_min) * 0.5 * (a[:, 0] + 1.0)
        c = s.c_max * a[:, 1]
        for i in range(n):
            i0 = integ[i] - c[i] if k == 0 else integ[i]
            ui, integ[i] = pi_scan1(i0, sp[i] - pv[i], s.Kc, ki, g[i], c[i], s.op_lo, s.op_hi, False)
            assert ui == u[i]
        np.testing.assert_array_equal(integ, law.state_arrays()["I"])
