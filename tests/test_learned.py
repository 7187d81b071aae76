"""The learned compensator as a DCS block: loading, scalar/batched use, bumpless start, integral action."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from valve_gym.agents.learned import (
    DEFAULT_POLICY,
    LearnedBlock,
    MLPSpec,
    load_learned,
    mlp_forward,
    normalise,
    save_learned,
)
from valve_gym.envs.regulation import N_ACT, N_OBS, BlockSettings, RegulationTaskConfig, pi_action
from valve_gym.envs.regulation_env import ValveTankRegulationVectorEnv

ROOT = Path(__file__).resolve().parents[1]


def _random_block(tmp_path, seed=0, hidden=(8,)):
    spec = MLPSpec(hidden)
    theta = np.random.default_rng(seed).standard_normal(spec.n_params) * 0.5
    save_learned(tmp_path / "blk", theta, spec, np.zeros(N_OBS), np.ones(N_OBS), BlockSettings(), {"seed": seed})
    return load_learned(tmp_path / "blk.json")


def test_shipped_block_loads_without_torch():
    code = ("import sys; from valve_gym.agents.learned import load_learned; b = load_learned(); "
            "b.reset(1.0, 1.0, 0.5); "
            "u = b.step(1.0, 1.002); assert 0 <= u <= 1; assert 'torch' not in sys.modules, 'torch imported'")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert DEFAULT_POLICY.is_file() and DEFAULT_POLICY.with_suffix(".safetensors").is_file()


def test_shipped_block_records_how_it_was_made():
    import json

    meta = json.loads(DEFAULT_POLICY.read_text())
    assert meta["train_command"].startswith("valve-gym train --config configs/learned.yaml")
    assert isinstance(meta["seed"], int) and meta["train_wall_s"] > 0
    assert meta["block"]["g_min"] > 0                     # integral action cannot be switched off
    assert "obs_mean" not in meta                         # statistics are in the weights file


def test_scalar_and_batched_agree(tmp_path):
    blk = _random_block(tmp_path)
    rng = np.random.default_rng(1)
    sp = np.array([0.8, 1.0, 1.2])
    pv = sp + 0.01 * rng.standard_normal((50, 3))
    op0 = np.array([0.4, 0.5, 0.6])
    blk.reset(sp, pv[0], op0)
    batched = np.array([blk.step(sp, pv[k]) for k in range(50)])
    for i in range(3):
        blk.reset(sp[i], pv[0, i], op0[i])
        single = [blk.step(sp[i], pv[k, i]) for k in range(50)]
        assert isinstance(single[0], float)
        np.testing.assert_allclose(single, batched[:, i], rtol=0, atol=1e-12)


def test_bumpless_start_and_output_limits(tmp_path):
    blk = load_learned()
    blk.reset(1.0, 1.0, 0.37)
    assert blk.step(1.0, 1.0) == pytest.approx(0.37, abs=1e-3)
    blk.reset(np.full(4, 1.0), np.full(4, 1.0), np.array([0.0, 0.2, 0.8, 1.0]))
    for _ in range(20):
        u = blk.step(1.0, np.array([0.5, 1.0, 1.0, 1.5]))
    assert u.shape == (4,) and np.all((u >= 0) & (u <= 1))


def test_block_equals_env_with_the_same_network(tmp_path):
    """The env's block law (training) and the DCS block (deployment) give the same outputs."""
    blk = _random_block(tmp_path, seed=3)
    cfg = RegulationTaskConfig(episode_s=120.0, block=blk.block_settings)
    env = ValveTankRegulationVectorEnv(4, cfg)
    obs, info = env.reset(seed=11)
    loops = env._loops
    pv0 = loops.plants.level + loops.draw.noise[:, 0]
    blk.reset(info["setpoint"], pv0, loops.plants.op0)
    pv = pv0
    for _ in range(100):
        u_blk = blk.step(info["setpoint"], pv)
        a = mlp_forward(blk.weights, normalise(obs.astype(float), blk.obs_mean, blk.obs_std))
        obs, r, te, tr, inf = env.step(a)
        np.testing.assert_allclose(inf["op"], u_blk, rtol=0, atol=1e-5)   # obs are float32 in the env
        pv = inf["pv"]


def test_integral_action_no_offset_on_a_sticky_valve():
    """Shipped block on sticky valves with a load step: the mean error of the last half hour is < 1 mm."""
    cfg = RegulationTaskConfig(episode_s=3600.0, load_std=(0.0, 0.0), noise_std=(0.002, 0.002))
    env = ValveTankRegulationVectorEnv(6, cfg)
    env.reset(seed=5, options={"S": [0.0, 0.01, 0.03, 0.05, 0.07, 0.09], "J": [0.0, 0.005, 0.01, 0.02, 0.03, 0.04],
                               "model": "choudhury", "level": 1.0})
    loops = env._loops
    loops.draw.load[:, 600:] = 2.0e-4                         # a 0.2 L/s load step after 10 min
    blk = load_learned()
    pv = loops.plants.level + loops.draw.noise[:, 0]
    blk.reset(1.0, pv, loops.plants.op0)
    errs = []
    for _ in range(cfg.steps):
        u = blk.step(1.0, pv)
        loops.law.reset(1.0, pv, u)                           # drive the plant with the block's output
        _, _, _, inf = loops.step(pi_action(6) * 0 + np.array([1.0, 0.0]))
        pv = inf["pv"]
        errs.append(1.0 - inf["level"])
    e = np.array(errs)[-1800:]
    assert np.all(np.abs(e.mean(axis=0)) < 1e-3), e.mean(axis=0)


def test_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown setting.*Kc"):
        load_learned(Kcc=2.0)
    with pytest.raises(FileNotFoundError):
        load_learned(tmp_path / "nope.json")
    with pytest.raises(FileNotFoundError, match="learned.json"):
        load_learned(tmp_path)
    blk = load_learned()
    with pytest.raises(ValueError, match=r"step\(\) called before reset\(\); call reset\(sp, pv, op\) first"):
        LearnedBlock(blk.weights, blk.obs_mean, blk.obs_std).step(1.0, 1.0)     # as every block says it
    blk.reset(1.0, 1.0, 0.5)
    with pytest.warns(RuntimeWarning, match="output held"):
        assert blk.step(1.0, float("nan")) == 0.5          # a bad PV holds the output (DCS bad-PV hold)
    assert blk.held.tolist() == [True] and blk.bad_pv_scans.tolist() == [1]
    with pytest.raises(ValueError, match="op"):
        blk.reset(1.0, 1.0, 1.5)
    with pytest.raises(ValueError, match="g_min"):
        load_learned(g_min=0.0)


def test_network_shapes():
    spec = MLPSpec((5, 4))
    theta = np.arange(spec.n_params, dtype=float) * 1e-3
    from valve_gym.agents.learned import unflatten

    w = unflatten(spec, theta)
    assert w["W0"].shape == (N_OBS, 5) and w["W2"].shape == (4, N_ACT)
    x = np.ones((3, N_OBS))
    y = mlp_forward(w, x)
    pop = {k: np.stack([v, v]) for k, v in w.items()}
    np.testing.assert_allclose(mlp_forward(pop, np.stack([x, x]))[1], y)
    assert y.shape == (3, N_ACT)


def test_stick_features_layout_and_roundtrip(tmp_path):
    from valve_gym.envs.regulation import STICK_OBS_NAMES, BlockLaw, obs_names

    bs = BlockSettings(stick_features=True)
    n_obs = len(obs_names(bs))
    assert n_obs == N_OBS + len(STICK_OBS_NAMES) and len(obs_names(BlockSettings())) == N_OBS
    law = BlockLaw(bs, 1)
    law.reset(1.0, 1.0, 0.5)
    # error stays positive: the output ramps (integral action) and the filtered error never changes sign,
    # so the output's move since the last sign change grows with it, and so does the time
    for _ in range(30):
        law.observe(1.0, 0.99)
        law.act(pi_action(1))
    o = law.observe(1.0, 0.99)[0]
    assert o[N_OBS] == pytest.approx((law.u[0] - 0.5) / bs.u_ref, rel=1e-9) and o[N_OBS] > 0
    # the filtered error turns negative: both are reset at the sign change
    for _ in range(60):
        law.act(pi_action(1))
        o = law.observe(1.0, 1.01)[0]
    assert o[N_OBS + 1] < 0.6 and abs(o[N_OBS]) < abs(law.u[0] - 0.5) / bs.u_ref
    spec = MLPSpec((8,), n_obs)
    theta = np.random.default_rng(0).standard_normal(spec.n_params) * 0.5
    save_learned(tmp_path / "stk", theta, spec, np.zeros(n_obs), np.ones(n_obs), bs, {"seed": 0})
    blk = load_learned(tmp_path / "stk.json")
    blk.reset(1.0, 1.0, 0.5)
    assert 0.0 <= blk.step(1.0, 1.003) <= 1.0
    env = ValveTankRegulationVectorEnv(2, RegulationTaskConfig(episode_s=10.0, block=bs))
    obs, _ = env.reset(seed=[1, 2])
    assert obs.shape == (2, n_obs) and env.single_observation_space.shape == (n_obs,)


def test_fitness_counts_limit_cycle_amplitude_on_sticky_valves_only():
    from valve_gym.agents.es import ESHyper, RolloutScores, fitness

    S = np.array([0.001, 0.03])                                # one healthy, one sticky loop
    ref_iae, ref_rev = np.array([1.0, 2.0]), np.array([10.0, 10.0])
    ref_lc, ref_amp = np.array([0.0, 1.0]), np.array([0.0, 0.02])

    def sc(amp):
        return RolloutScores(np.array([[1.0, 2.0]]), np.zeros((1, 2)), np.array([[10.0, 10.0]]),
                             np.array([[0.0, 1.0]]), np.zeros(N_OBS), np.ones(N_OBS), S, np.array([amp]))

    h = ESHyper(travel_penalty=0.0, reversal_weight=0.0, lc_weight=0.0, lc_amp_weight=1.0)
    f_same = fitness(sc([0.0, 0.02]), ref_iae, ref_rev, h, 1.0, ref_lc=ref_lc, ref_lc_amp=ref_amp)[0]
    f_half = fitness(sc([0.0, 0.01]), ref_iae, ref_rev, h, 1.0, ref_lc=ref_lc, ref_lc_amp=ref_amp)[0]
    f_healthy = fitness(sc([0.05, 0.02]), ref_iae, ref_rev, h, 1.0, ref_lc=ref_lc, ref_lc_amp=ref_amp)[0]
    assert f_same == pytest.approx(0.0) and f_healthy == pytest.approx(0.0)
    assert f_half == pytest.approx(0.5 * 1.0)                  # 1 cm less on one of two loops, weight 1 per cm
