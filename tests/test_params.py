"""Tests of valve_gym.params: validation, effects, batch size, immutable variants."""

from __future__ import annotations

import dataclasses
import doctest
from dataclasses import fields, replace

import numpy as np
import pytest

from valve_gym import params as pmod
from valve_gym.params import (
    EFFECTS,
    PROCESSES,
    Actuator,
    Cascade,
    DeadTime,
    FirstOrderParams,
    IntegratingParams,
    Leak,
    ModelParams,
    OscillatingDisturbance,
    Overflow,
    ParameterError,
    SensorLag,
    SlipJump,
    TankParams,
    ValveCharacteristic,
    ValveParams,
)

ALL_BLOCKS = [ValveParams, SlipJump, ValveCharacteristic, DeadTime, Overflow, Leak, SensorLag,
              OscillatingDisturbance, Cascade, Actuator, TankParams, IntegratingParams,
              FirstOrderParams, ModelParams]


def test_module_doctest():
    res = doctest.testmod(pmod, optionflags=doctest.ELLIPSIS)
    assert res.failed == 0 and res.attempted > 0


# --------------------------------------------------------------------------
# defaults and immutability
# --------------------------------------------------------------------------


@pytest.mark.parametrize("cls", ALL_BLOCKS)
def test_defaults_are_valid_and_frozen(cls):
    obj = cls()
    obj.validate()
    f = fields(obj)[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(obj, f.name, getattr(obj, f.name))


def test_paper_healthy_valve_defaults():
    v = ValveParams()
    assert (v.tau, v.z_max, v.e_dead) == (0.1, 0.005, 0.005)


def test_model_defaults():
    p = ModelParams()
    assert p.process_kind == "tank" and isinstance(p.process, TankParams)
    assert p.effects == ()
    assert p.batch_size() == 1


# --------------------------------------------------------------------------
# field validation: every bad value names Class.field and the allowed range
# --------------------------------------------------------------------------

BAD_VALUES = [
    (ValveParams, "tau", 0.0, "> 0"),
    (ValveParams, "tau", -0.1, "> 0"),
    (ValveParams, "v_max", 0.0, "> 0"),
    (ValveParams, "e_dead", -0.01, ">= 0"),
    (ValveParams, "e_dead", 0.6, "<= 0.5"),
    (ValveParams, "z_max", -1e-3, ">= 0"),
    (SlipJump, "S", -0.1, ">= 0"),
    (SlipJump, "S", 1.5, "<= 1"),
    (SlipJump, "J", -0.1, ">= 0"),
    (SlipJump, "tau_p", 0.0, "> 0"),
    (ValveCharacteristic, "R", 1.0, "> 1"),
    (ValveCharacteristic, "h0", -0.1, ">= 0"),
    (ValveCharacteristic, "h0", 0.995, "<= 0.99"),
    (DeadTime, "theta", -1.0, ">= 0"),
    (Overflow, "L_max", 0.0, "> 0"),
    (Overflow, "L2_max", -1.0, "> 0"),
    (Overflow, "spill_to_lower", 1.5, "<= 1"),
    (Leak, "q_leak", -1e-4, ">= 0"),
    (SensorLag, "tau_s", 0.0, "> 0"),
    (OscillatingDisturbance, "amplitude", -1e-4, ">= 0"),
    (OscillatingDisturbance, "period", 0.0, "> 0"),
    (Cascade, "area2", 0.0, "> 0"),
    (Cascade, "k_out2", -1.0, ">= 0"),
    (Cascade, "level2_0", -1.0, ">= 0"),
    (TankParams, "area", 0.0, "> 0"),
    (TankParams, "q_max", -1.0, "> 0"),
    (TankParams, "k_out", -1.0, ">= 0"),
    (TankParams, "level0", -0.5, ">= 0"),
    (IntegratingParams, "area", 0.0, "> 0"),
    (FirstOrderParams, "T", 0.0, "> 0"),
]


@pytest.mark.parametrize("cls,name,value,rule", BAD_VALUES,
                         ids=[f"{c.__name__}.{n}={v}" for c, n, v, _ in BAD_VALUES])
def test_out_of_range_value_names_field_and_rule(cls, name, value, rule):
    with pytest.raises(ParameterError) as exc:
        cls(**{name: value})
    msg = str(exc.value)
    assert f"{cls.__name__}.{name}" in msg
    assert rule in msg
    # the error is also a ValueError, for callers that catch that
    assert isinstance(exc.value, ValueError)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
@pytest.mark.parametrize("name", ["tau", "e_dead", "z_max"])
def test_non_finite_value_rejected(name, bad):
    with pytest.raises(ParameterError, match=rf"ValveParams\.{name} must be a finite number"):
        ValveParams(**{name: bad})


def test_infinite_allowed_where_documented():
    assert ValveParams(v_max=float("inf")).v_max == float("inf")
    assert Overflow(L2_max=float("inf")).L2_max == float("inf")


def test_array_fields_are_checked_elementwise():
    ValveParams(tau=np.array([0.05, 0.1, 0.2]))
    with pytest.raises(ParameterError, match=r"ValveParams\.tau.*-0\.1"):
        ValveParams(tau=np.array([0.1, -0.1, 0.2]))
    with pytest.raises(ParameterError, match=r"ValveParams\.z_max must be a finite number"):
        ValveParams(z_max=np.array([0.1, np.nan]))


@pytest.mark.parametrize("cls,kind", [(ValveCharacteristic, "logarithmic"),
                                      (Actuator, "motor")])
def test_unknown_kind(cls, kind):
    with pytest.raises(ParameterError, match=rf"{cls.__name__}\.kind must be") as exc:
        cls(kind=kind)
    assert kind in str(exc.value)


def test_characteristic_codes():
    assert [ValveCharacteristic(kind=k).code for k in
            ("linear", "equal_percentage", "quick_opening")] == [0, 1, 2]


# --------------------------------------------------------------------------
# ModelParams structure
# --------------------------------------------------------------------------


def test_unknown_process_kind():
    with pytest.raises(ParameterError, match="process_kind must be one of"):
        ModelParams(process_kind="pipe")


@pytest.mark.parametrize("kind,proc", [("tank", IntegratingParams()),
                                       ("integrating", TankParams()),
                                       ("first_order", TankParams())])
def test_process_must_match_kind(kind, proc):
    with pytest.raises(ParameterError, match=rf"process_kind='{kind}' needs process="):
        ModelParams(process_kind=kind, process=proc)


def test_process_kinds_accept_their_process():
    for kind, cls in PROCESSES.items():
        extra = {"cascade": Cascade()} if kind == "cascade" else {}
        assert ModelParams(process_kind=kind, process=cls(), **extra).process_kind == kind


def test_cascade_kind_and_block_go_together():
    with pytest.raises(ParameterError, match="set both or neither"):
        ModelParams(process_kind="cascade")
    with pytest.raises(ParameterError, match="set both or neither"):
        ModelParams(cascade=Cascade())


@pytest.mark.parametrize("dt", [0.0, -0.01, float("nan"), float("inf"), "0.02", None])
def test_bad_dt(dt):
    with pytest.raises(ParameterError, match="ModelParams.dt must be a positive number of seconds"):
        ModelParams(dt=dt)


@pytest.mark.parametrize("name", sorted(EFFECTS))
def test_effect_slot_type_checked(name):
    extra = {"process_kind": "cascade"} if name == "cascade" else {}
    with pytest.raises(ParameterError, match=rf"ModelParams\.{name} must be a"):
        ModelParams(**{name: 1.0}, **extra)


def test_effects_are_the_optional_fields():
    optional = [f.name for f in fields(ModelParams) if f.name not in ("valve", "process",
                                                                       "process_kind", "dt")]
    assert optional == list(EFFECTS)


# --------------------------------------------------------------------------
# with_effect / effects
# --------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(EFFECTS))
def test_with_effect_default_block(name):
    base = ModelParams()
    if name == "cascade":
        base = replace(base, process_kind="cascade", cascade=Cascade())
        assert base.effects == ("cascade",)
        return
    p = base.with_effect(name)
    assert isinstance(getattr(p, name), EFFECTS[name])
    assert getattr(p, name) == EFFECTS[name]()
    assert p.effects == (name,)
    assert base.effects == ()  # the original is untouched


def test_with_effect_given_block_and_order():
    p = ModelParams().with_effect("leak", Leak(q_leak=1e-3)).with_effect("dead_time",
                                                                         DeadTime(theta=3.0))
    assert p.leak.q_leak == 1e-3 and p.dead_time.theta == 3.0
    # effects are listed in the canonical order of EFFECTS, not insertion order
    assert p.effects == ("dead_time", "leak")


def test_with_effect_unknown_name_lists_known():
    with pytest.raises(ParameterError, match="unknown effect 'stiction'") as exc:
        ModelParams().with_effect("stiction")
    assert "slip_jump" in str(exc.value)


def test_with_effect_wrong_block_type():
    with pytest.raises(ParameterError, match=r"ModelParams\.leak must be a Leak"):
        ModelParams().with_effect("leak", DeadTime())


def test_switching_effect_off_with_replace():
    p = ModelParams().with_effect("sensor_lag")
    assert replace(p, sensor_lag=None).effects == ()


# --------------------------------------------------------------------------
# batch size
# --------------------------------------------------------------------------


def test_batch_size_from_arrays():
    v = ValveParams(z_max=np.array([0.0, 0.1, 0.2]), e_dead=np.array([0.0, 0.01, 0.02]))
    p = ModelParams(valve=v, leak=Leak(q_leak=np.array([0.0, 1e-4, 2e-4])))
    assert p.batch_size() == 3


def test_batch_size_length_one_arrays_broadcast():
    p = ModelParams(valve=ValveParams(tau=np.array([0.1])),
                    process=TankParams(area=np.array([0.1, 0.2, 0.3, 0.4])))
    assert p.batch_size() == 4


def test_batch_size_mismatch_names_the_field():
    p = ModelParams(valve=ValveParams(z_max=np.array([0.1, 0.2, 0.3])),
                    process=TankParams(area=np.array([0.1, 0.2])))
    with pytest.raises(ParameterError, match=r"TankParams\.area has batch size 2 but another "
                                             r"parameter has 3"):
        p.batch_size()


# --------------------------------------------------------------------------
# replace re-validates
# --------------------------------------------------------------------------


def test_replace_makes_a_validated_variant():
    v = ValveParams()
    sticky = replace(v, z_max=0.2, e_dead=0.01)
    assert (sticky.z_max, sticky.e_dead, sticky.tau) == (0.2, 0.01, v.tau)
    assert v.z_max == 0.005
    with pytest.raises(ParameterError, match=r"ValveParams\.tau"):
        replace(v, tau=-1.0)
    with pytest.raises(ParameterError, match="ModelParams.dt"):
        replace(ModelParams(), dt=0.0)


def test_params_are_hashable_values():
    # frozen dataclasses of floats compare by value (handy as dict keys for configs)
    assert ValveParams(z_max=0.1) == ValveParams(z_max=0.1)
    assert hash(ValveParams(z_max=0.1)) == hash(ValveParams(z_max=0.1))
    assert ModelParams() == ModelParams()


# --------------------------------------------------------------------------
# slip_jump laws and the friction model name
# --------------------------------------------------------------------------

NEW_BAD = [("omega_n", 0.0, "> 0"), ("omega_n", float("nan"), "finite"), ("zeta", -0.1, ">= 0"),
           ("dv", 0.0, "> 0"), ("tau_p", -1.0, "> 0")]


@pytest.mark.parametrize("name,value,rule", NEW_BAD)
@pytest.mark.parametrize("law", ["choudhury", "kano", "karnopp"])
def test_slip_jump_law_fields_validated(law, name, value, rule):
    with pytest.raises(ParameterError, match=rf"SlipJump\.{name}.*{rule}"):
        SlipJump(law=law, **{name: value})


def test_slip_jump_law_names():
    assert pmod.SLIP_JUMP_LAWS == ("choudhury", "kano", "karnopp")
    assert SlipJump().law == "choudhury"
    with pytest.raises(ParameterError, match="law must be one of .*'kano'"):
        SlipJump(law="Kano")
    with pytest.raises(ParameterError, match="kernel law"):
        pmod.register_sample_law("kano")
    # overshoot is allowed for the data-driven laws, not for the force balance
    SlipJump(S=0.02, J=0.03, law="kano")
    with pytest.raises(ParameterError, match="J must be <= S"):
        SlipJump(S=np.array([0.02, 0.02]), J=np.array([0.01, 0.03]), law="karnopp")


def test_friction_model_follows_the_blocks():
    assert ModelParams().friction_model == "riihilahti"
    assert ModelParams(valve=ValveParams(e_dead=np.zeros(2), z_max=np.zeros(2))).friction_model == "none"
    assert ModelParams(slip_jump=SlipJump(law="karnopp")).friction_model == "karnopp"
    # friction laws are not effects: the optional blocks stay those of EFFECTS
    assert ModelParams(slip_jump=SlipJump(law="kano")).effects == ("slip_jump",)


def test_batch_size_sees_law_parameters():
    p = ModelParams(slip_jump=SlipJump(law="karnopp", omega_n=np.array([50.0, 100.0, 200.0])))
    assert p.batch_size() == 3
