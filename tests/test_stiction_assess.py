"""The combined stiction assessment inside the diagnosis, and the S/J estimates with intervals."""
import pytest

from valve_gym.diagnosis import diagnose
from valve_gym.diagnosis.diagnose import coarse_factor
from valve_gym.diagnosis.stiction import assess_stiction, default_model
from valve_gym.diagnosis.stiction.loops import LoopSpec, simulate_loop

STICKY = LoopSpec(process="integrating", valve="kano", S=0.05, J=0.02, k_i=0.02, Kc=4.0, Ti=60.0, Ts=1.0,
                  theta=2.0, noise=0.0003, tau_v=0.2, n=900, sp_step=0.02)


@pytest.fixture(scope="module")
def sticky_result():
    return diagnose(simulate_loop(STICKY, seed=3), plant="integrating", candidates=(), effort="fast")


def test_diagnosis_reports_probability_and_sizes(sticky_result):
    s = sticky_result.to_dict()["stiction"]
    for k in ("probability", "verdict", "S", "J", "S_interval", "J_interval", "evidence", "model_based_present"):
        assert k in s
    assert 0.0 <= s["probability"] <= 1.0
    assert s["verdict"] in ("stiction", "no stiction", "undecided")
    # the public verdict: the combination says stiction or the model-based verdict finds friction
    assert s["present"] is (s["verdict"] == "stiction" or s["model_based_present"])
    assert {e["method"] for e in s["evidence"]} == {"horch", "bicoherence", "ellipse", "waveform", "episodes",
                                                   "hammerstein"}
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

