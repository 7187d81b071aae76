"""``plant='auto'``: the process model from the loop tag in a recording's name."""
from __future__ import annotations

import csv

import pytest

from valve_gym.diagnosis import data_path
from valve_gym.diagnosis.plant_choice import plant_from_name, resolve_plant


@pytest.mark.parametrize("name, plant", [
    ("2411FIC20102_0609_0957", "first_order"), ("FIC-211_sorted", "first_order"),
    ("stiction__2_CDU.7040-311_FIC31102_0628_0002", "first_order"), ("2111PIC86501", "first_order"),
    ("TC-5", "first_order"), ("2411AIC90201_1002", "first_order"), ("reactor_TRC_12", "first_order"),
    ("no_stiction__2111LIC23001_1110_0008", "integrating"), ("LIC-106_sorted", "integrating"),
    ("lc 7", "integrating"),
    # no tag: the package's level tank; "STICTION", "ELASTIC1" hold the letters inside words
    ("leak_100", "tank"), ("no_stiction_loop", "tank"), ("elastic1", "tank"), ("estimation", "tank"),
    ("FIC1_LIC2", "tank"),                                                # both kinds: ambiguous
])
def test_plant_from_the_tag(name, plant):
    chosen, why = plant_from_name(name)
    assert chosen == plant and f"'{plant}'" in why and "--plant" in why


def test_every_labelled_plant_loop_gets_the_model_it_was_validated_with():
    """The held-out stiction validation diagnosed level loops as integrating, all others as first order."""
    folder = data_path("stictiongpt_plant_loops")
    rows = list(csv.DictReader(open(folder / "index.csv", encoding="utf-8")))
    assert len(rows) == 49
    for r in rows:
        want = "integrating" if r["loop_type"] == "LIC" else "first_order"
        assert plant_from_name(r["csv_file"].rsplit("/", 1)[-1][:-4])[0] == want, r["csv_file"]


@pytest.mark.parametrize("column, plant", [
    ("flow_FT115", "first_order"),       # a level loop's file whose PV is the flow through its valve
    ("LT-101", "integrating"), ("2411LIC10201.PV", "integrating"), ("PV_pressure", "first_order"),
    ("level", "integrating"),            # "level" alone decides nothing: the name's LIC does
    ("PV", "integrating"),
])
def test_the_pv_column_is_read_before_the_name(column, plant):
    chosen, why = plant_from_name("LIC-106_sorted", pv_column=column)
    assert chosen == plant
    assert ("PV column" in why) == (plant == "first_order" or column == "LT-101" or ".PV" in column)


def test_a_level_column_keeps_the_tank_model_without_a_tag():
    assert plant_from_name("rig_run_3", pv_column="level")[0] == "tank"


def test_a_named_model_is_kept():
    assert resolve_plant("cascade", "FIC101") == ("cascade", {"asked": "cascade", "chosen": "cascade"})
    assert resolve_plant("auto", "FIC101")[1]["chosen"] == "first_order"
