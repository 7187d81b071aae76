"""PI controller contracts and the shared ``predict`` interface of all controllers."""
import numpy as np
import pytest

from valve_gym.agents import BlockPolicy, load_controller
from valve_gym.agents.base import Controller, action_to_u
from valve_gym.agents.controllers.tuning import default_tuning, simc_pi, tank_model
from valve_gym.core import initial_state, step
from valve_gym.params import ModelParams, TankParams, ValveParams

N_SUB = 50


def pi_policy(**kw):
    """The PI block with SB3's ``predict``."""
    return BlockPolicy(load_controller("pi", **kw))


def knocker_policy(**kw):
    return BlockPolicy(load_controller("knocker", **kw))
  # Euler steps of 0.02 s per 1 s control period


def _closed_loop(ctrl, valve, sp, d=None, level0=1.0):
    """PI(+) on the core's tank + valve, one controller period per sample."""
    n = 1
    p = ModelParams(valve=valve)
    s = initial_state(p, n=n, level=level0)
    T = len(sp)
    d = np.zeros(T) if d is None else d
    y = s.y.copy()
    u_prev = s.h.copy()
    state = None
    ys, us = [], []
    for k in range(T):
        obs = np.column_stack([y, [sp[k]], [sp[k] - y[0]], u_prev])
        a, state = ctrl.predict(obs, state)
        u = action_to_u(a)
        s, y = step(s, u, p, d=np.array([d[k]]), n_sub=N_SUB)
        ys.append(y[0])
        us.append(u[0])
        u_prev = u
    return np.array(ys), np.array(us)


FREE = ValveParams(z_max=0.0, e_dead=0.0)


def test_default_tuning_is_simc_for_default_tank():
    K, T = tank_model(TankParams(), 1.0)
    assert K == pytest.approx(4.0) and T == pytest.approx(80.0)
    t = default_tuning()
    assert (t.Kc, t.Ti) == pytest.approx(simc_pi(4.0, 80.0, 0.6, 10.0))
    pi = load_controller("pi")
    assert pi.settings["Kc"] == pytest.approx(t.Kc) and pi.settings["Ti"] == pytest.approx(t.Ti)


def test_pi_removes_steady_state_error_friction_free():
    T = 600
    sp = np.full(T, 1.0)
    sp[20:] = 1.1                      # set-point step
    d = np.zeros(T)
    d[300:] = -0.0015                  # load: an extra offtake of 15 % of q_max
    y, u = _closed_loop(pi_policy(), FREE, sp, d)
    assert abs(y[290] - 1.1) < 1e-3    # set point reached
    assert abs(y[-1] - 1.1) < 1e-3     # load rejected, no offset
    assert u[-1] > u[290] + 0.1        # by opening the valve
    assert y[20:300].max() < 1.1 + 0.02  # about 5 % overshoot of the 0.1 m step at most


def test_pi_anti_windup_controller_level():
    pi = pi_policy(Kc=2.0, Ti=20.0)
    obs = np.array([[0.5, 1.0, 0.5, 0.5]])
    s = None
    for _ in range(200):              # a large positive error for a long time
        a, s = pi.predict(obs, s)
    assert s is not None
    assert action_to_u(a)[0] == 1.0 and s.op[0] == 1.0    # saturated
    assert s.integral[0] == pytest.approx(1.0 - 2.0 * 0.5)  # integral tracks the limit: I = 1 - Kc e
    obs[0, 2] = -0.01                 # error changes sign
    a, s = pi.predict(obs, s)
    assert action_to_u(a)[0] < 1.0    # leaves saturation at the very next sample


def test_pi_anti_windup_closed_loop_no_hang():
    T = 500
    sp = np.full(T, 1.0)
    d = np.zeros(T)
    d[10:150] = -0.011                # offtake larger than the valve can supply
    y, u = _closed_loop(pi_policy(), FREE, sp, d)
    assert np.all(u[60:150] == 1.0)   # saturated while the load is on
    # after the load goes, the valve comes off the limit within a few samples
    # of the level passing the set point, and the overshoot stays small
    cross = 150 + np.argmax(y[150:] >= 1.0)
    assert u[cross + 5] < 1.0
    assert y[150:].max() < 1.0 + 0.1


def test_pi_bumpless_start():
    pi = pi_policy(Kc=3.0, Ti=30.0)
    obs = np.array([[1.0, 1.0, 0.0, 0.37], [0.95, 1.0, 0.05, 0.6]])
    a, _ = pi.predict(obs)
    u = action_to_u(a)
    assert u[0] == pytest.approx(0.37, abs=1e-6)           # no error: output unchanged
    assert u[1] == pytest.approx(0.6 + 3.0 / 30.0 * 0.05, abs=1e-6)  # no proportional kick
    # restart of one row only through episode_start
    _, s = pi.predict(obs)
    obs2 = obs.copy()
    obs2[:, 3] = [0.1, 0.9]
    a2, _ = pi.predict(obs2, s, episode_start=np.array([True, False]))
    assert action_to_u(a2)[0] == pytest.approx(0.1, abs=1e-6)


def test_pi_bad_input():
    with pytest.raises(ValueError, match=r"Kc = -1.0 is out of range; allowed: Kc \[1/m\] in \(0"):
        pi_policy(Kc=-1.0, Ti=10.0)
    with pytest.raises(ValueError, match=r"Ti = 0.0 is out of range; allowed: Ti \[s\] in \(0"):
        pi_policy(Kc=1.0, Ti=0.0)
    with pytest.raises(ValueError, match="Kc must be a number"):
        pi_policy(Kc="1", Ti=10.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="at least 4"):
        pi_policy().predict(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="NaN"):
        pi_policy().predict(np.full((1, 4), np.nan))


@pytest.mark.parametrize("make", [pi_policy, knocker_policy])
def test_predict_signature_and_batch_shapes(make):
    ctrl = make()
    assert isinstance(ctrl, Controller)
    rng = np.random.default_rng(1)
    for n in (1, 3, 17):
        obs = np.column_stack([rng.uniform(0.5, 1.5, n), np.ones(n), rng.normal(0, 0.1, n),
                               rng.uniform(0, 1, n)]).astype(np.float32)
        a, s = ctrl.predict(obs, state=None, episode_start=np.ones(n, bool), deterministic=True)
        assert a.shape == (n, 1) and a.dtype == np.float32
        assert np.all(np.abs(a) <= 1.0)
        a2, s2 = ctrl.predict(obs, s, np.zeros(n, bool))
        assert a2.shape == (n, 1)
    single, _ = ctrl.predict(obs[0])
    assert single.shape == (1,)


def _untrained_ppo(transform, mode="direct"):
    import gymnasium as gym
    from stable_baselines3 import PPO

    from valve_gym.agents.ppo import PPOController

    d = transform.out_dim(4)
    space = gym.spaces.Box(-np.inf, np.inf, (d,), np.float32)

    class Dummy(gym.Env):
        observation_space = space
        action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

        def reset(self, seed=None, options=None):
            return np.zeros(d, np.float32), {}

        def step(self, a):
            return np.zeros(d, np.float32), 0.0, False, False, {}

    model = PPO("MlpPolicy", Dummy(), n_steps=64, batch_size=64, device="cpu",
                policy_kwargs={"net_arch": [8]})
    return PPOController(model, transform=transform, env_mode=mode)


def test_ppo_predict_signature_and_batch_shapes():
    from valve_gym.agents.ppo import ObsTransform, PPOState

    ctrl = _untrained_ppo(ObsTransform(frame_stack=3, deltas=True))
    assert isinstance(ctrl, Controller)
    rng = np.random.default_rng(2)
    obs = np.column_stack([rng.uniform(0.5, 1.5, 7), np.ones(7), rng.normal(0, 0.1, 7),
                           rng.uniform(0, 1, 7)]).astype(np.float32)
    a, s = ctrl.predict(obs, state=None, episode_start=np.ones(7, bool), deterministic=True)
    assert a.shape == (7, 1) and a.dtype == np.float32 and isinstance(s, PPOState)
    assert s.hist.frames.shape == (7, 3, 4)
    a2, s2 = ctrl.predict(obs * 1.01, s, np.zeros(7, bool))
    assert a2.shape == (7, 1) and not np.array_equal(s2.hist.frames, s.hist.frames)
    # deterministic: same history, same action
    a3, _ = ctrl.predict(obs * 1.01, s, np.zeros(7, bool))
    assert np.array_equal(a2, a3)


def test_obs_transform_history_and_restart():
    from valve_gym.agents.ppo import ObsTransform

    tf = ObsTransform(frame_stack=2, deltas=True)
    o1 = np.array([[1.0, 1.0, 0.0, 0.5], [1.2, 1.0, -0.2, 0.4]])
    x, h = tf.start(o1)
    f1 = tf.features(o1)
    assert np.allclose(x[:, :4], f1) and np.allclose(x[:, 4:8], f1) and np.allclose(x[:, 8:], 0)
    o2 = o1 + 0.1
    x2, h2 = tf.step(h, o2, episode_start=np.array([False, True]))
    f2 = tf.features(o2)
    assert np.allclose(x2[0, :4], f1[0]) and np.allclose(x2[0, 4:8], f2[0])      # oldest first
    assert np.allclose(x2[0, 8:], f2[0] - f1[0])
    assert np.allclose(x2[1, :4], f2[1]) and np.allclose(x2[1, 8:], 0)           # restarted row
    with pytest.raises(ValueError, match="frame_stack"):
        ObsTransform(frame_stack=0)
