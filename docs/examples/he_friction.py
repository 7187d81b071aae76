"""``he``: the semi-physical stiction model of He, Wang, Pottmann & Qin (2007), as one file.

A worked example of adding a friction model to valve_gym without touching the
package (``docs/extending.md``): this module declares the model's spec and its
per-sample law; importing it registers ``"he"``, after which
``valve_model("he", S, J)`` builds it and :class:`valve_gym.plant.Plant` runs it.
``tests/test_friction_models.py`` imports this file and checks it against the
paper's behaviour.

Notes
-----
With the residual force ``u_r`` (in input units), static band ``fs`` and
kinetic band ``fd``, once per sample::

    cum = u_r + u(k) - u(k-1)
    if |cum| > fs:  x(k) = u(k) - sign(cum) fd,   u_r = sign(cum) fd      (slips)
    else:           x(k) = x(k-1),                u_r = cum                (sticks)

After a reversal the input must move ``fs + fd`` and the slip jumps
``fs - fd``, so ``S = fs + fd`` and ``J = fs - fd`` (``J <= S``; no overshoot).
Unlike Choudhury's and Kano's models, ``u_r`` is reset at every slip, so with
per-sample input steps smaller than ``J`` the stem moves in a staircase of steps
of about ``J`` even without reversals (oracle O6); it equals Choudhury's model
when ``J = 0``.

References
----------
.. [1] Q.P. He, J. Wang, M. Pottmann, S.J. Qin, "A curve fitting method for
   detecting valve stiction in oscillating control loops", Industrial &
   Engineering Chemistry Research 46 (2007) 4549-4560.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from valve_gym.friction.spec import FrictionSpec, ParamSpec, register
from valve_gym.params import ModelParams, SlipJump

ROW_X, ROW_U, ROW_UR = 0, 1, 2            # rows of the plant-kept memory this law uses


def build(base: ModelParams, S, J) -> ModelParams:
    """``base`` (friction removed) with ``SlipJump(S, J, tau_p = base.valve.tau, law='he')``."""
    return replace(base, slip_jump=SlipJump(S=S, J=J, tau_p=base.valve.tau, law="he"))


def he_sample(u: np.ndarray, mem: np.ndarray, block: SlipJump) -> np.ndarray:
    """One sample of He's model for ``n`` loops: input ``u`` (n,), state in ``mem``; returns ``x`` (n,)."""
    S = np.asarray(block.S, float)
    J = np.asarray(block.J, float)
    fs, fd = (S + J) / 2.0, (S - J) / 2.0
    cum = mem[ROW_UR] + u - mem[ROW_U]
    slip = np.abs(cum) > fs
    sg = np.sign(cum)
    x = np.where(slip, u - sg * fd, mem[ROW_X])
    mem[ROW_UR] = np.where(slip, sg * fd, cum)
    mem[ROW_X] = x
    mem[ROW_U] = u
    return x


SPEC = register(FrictionSpec(
    name="he",
    title="He et al. semi-physical stiction",
    params=(ParamSpec("S", "-", 0.0, 0.99, 0.02, "sq", "fs + fd, fraction of stroke"),
            ParamSpec("J", "-", 0.0, 0.99, 0.01, "lin", "fs - fd, fraction of stroke (J <= S)"),
            ParamSpec("tau_p", "s", 1e-3, 10.0, 0.1, "fixed", "positioner time constant (from the base valve)")),
    kernel="per-sample law outside the kernel: valve_gym.plant.Plant applies it once per scan; the core runs "
           "the positioner lag on its output.",
    signature="Flat stem for S of input after a reversal, then a jump J; under slow monotone inputs a staircase "
              "of steps of about J (re-sticks after every slip).",
    report="Stiction (He et al. 2007): static band fs = (S + J)/2 and kinetic band fd = (S - J)/2 with S = {S} % "
           "and J = {J} % of stroke; slow inputs move the stem in steps of about J.",
    citation="Q.P. He, J. Wang, M. Pottmann, S.J. Qin, \"A curve fitting method for detecting valve stiction in "
             "oscillating control loops\", Ind. Eng. Chem. Res. 46 (2007) 4549-4560.",
    build=build,
    sample_law=he_sample,
))
