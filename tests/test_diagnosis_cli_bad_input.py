"""``valve-gym diagnose`` refuses bad output paths, a Ray address nobody answers and an output range that
leaves the output constant, before any work; a negative-sign range is read; a final model that fits worse
than the record's mean says so."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from valve_gym.diagnosis import cli
from valve_gym.diagnosis.diagnose import _note_poor_fit
from valve_gym.diagnosis.synthetic import make_recording, write_csv

FAST = ["--effects", "none", "--effort", "fast", "--jobs", "1", "--quiet"]


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    p = tmp_path_factory.mktemp("bad_input") / "loop.csv"
    write_csv(make_recording("none", seed=4, n=300), p)
    return p


def run(argv, capsys):
    code = cli.main([str(a) for a in argv])
    _, err = capsys.readouterr()
    assert "Traceback" not in err
    return code, err


def test_output_paths_that_cannot_be_written_are_refused_first(loop, tmp_path, capsys):
    code, err = run([loop, "--op-range", "0,100", *FAST, "--report", loop.parent / "loop.csv" / "rep"], capsys)
    assert code == 2 and "is a file, not a folder" in err
    code, err = run([loop, "--op-range", "0,100", *FAST, "--json", loop.parent / "loop.csv" / "x.json"], capsys)
    assert code == 2 and "is a file, not a folder" in err
    both = tmp_path / "same"
    code, err = run([loop, "--op-range", "0,100", *FAST, "--json", both, "--report", both], capsys)
    assert code == 2 and "name the same path" in err and not both.exists()
    code, err = run([loop, "--op-range", "0,100", *FAST, "--json", ""], capsys)
    assert code == 2 and "--json is empty" in err


def test_a_ray_address_nobody_answers_is_refused_at_once(loop, tmp_path, capsys):
    out = tmp_path / "fleet"
    code, err = run([loop, "--op-range", "0,100", *FAST, "--out", out, "--address", "127.0.0.1:9"], capsys)
    assert code == 2 and "no Ray cluster answers there" in err and "ray start --head" in err
    code, err = run([loop, "--op-range", "0,100", *FAST, "--out", out, "--address", "garbage"], capsys)
    assert code == 2 and "HOST:PORT" in err


def test_ranges_with_a_minus_sign_and_their_own_flag_in_messages(loop, tmp_path, capsys):
    # parsed (not argparse's "expected one argument"): the run gets as far as the output check
    code, err = run([loop, "--op-range", "-1,0", *FAST, "--json", tmp_path / "no" / "x.json"], capsys)
    assert code == 2 and "expected one argument" not in err and "does not exist; create it first" in err
    code, err = run([loop, "--op-range", "0,100", "--mv-range", "a,b", *FAST], capsys)
    assert code == 2 and "e.g. --mv-range 0,100" in err


def test_an_output_range_that_leaves_the_output_constant_is_refused(loop, capsys):
    code, err = run([loop, "--op-range", "0,1e308", *FAST], capsys)
    assert code == 2 and "moves over only" in err and "--op-range" in err


def test_a_final_model_worse_than_the_mean_is_flagged():
    expl = ["No candidate effect pays."]
    _note_poor_fit(expl, SimpleNamespace(fit_percent_all=-14.8), "tank")
    assert len(expl) == 2 and expl[1].startswith("Caution: the final model fits the record worse than a constant")
    assert "(fit -14.8 %)" in expl[1] and "--plant" in expl[1]
    expl = ["x"]
    _note_poor_fit(expl, SimpleNamespace(fit_percent_all=35.0), "tank")
    assert expl == ["x"]


def test_empty_or_contradictory_options_are_refused(loop, capsys):
    code, err = run([loop, "--op-range", "0,100", *FAST[2:], "--effects", ""], capsys)
    assert code == 2 and "--effects is empty" in err
    code, err = run([loop, "--op-range", "0,100", *FAST[2:], "--effects", "none,slip_jump"], capsys)
    assert code == 2 and "'none' stands alone" in err
    code, err = run([loop, "--op-range", "0,100", *FAST, "--columns", ""], capsys)
    assert code == 2 and "empty column mapping" in err


def test_utf16_text_and_a_column_of_inf_are_named(loop, tmp_path, capsys):
    text = loop.read_text()
    u16 = tmp_path / "u16.csv"
    u16.write_bytes(text.encode("utf-16"))
    code, err = run([u16, "--op-range", "0,100", *FAST], capsys)
    assert code == 2 and "UTF-16" in err and "UTF-8" in err
    lines = text.splitlines()
    head = lines[0].split(",")
    k = head.index("SP")
    rows = [",".join("inf" if j == k else c for j, c in enumerate(r.split(","))) for r in lines[1:]]
    bad = tmp_path / "infsp.csv"
    bad.write_text("\n".join([lines[0]] + rows) + "\n")
    code, err = run([bad, "--op-range", "0,100", *FAST], capsys)
    assert code == 2 and "has no finite values" in err and "--columns sp=" in err


def test_column_problems_are_named(loop, tmp_path, capsys):
    lines = loop.read_text().splitlines()
    head = lines[0].split(",")                                    # t_s, OP, PV, SP
    dup = tmp_path / "dup.csv"
    dup.write_text("\n".join([",".join(head[:2] + head[1:2] + head[2:3])]
                             + [",".join(r.split(",")[:2] + r.split(",")[1:3]) for r in lines[1:]]) + "\n")
    code, err = run([dup, "--op-range", "0,100", *FAST], capsys)
    assert code == 2 and "the header names 'OP' 2 times (columns 2, 3)" in err
    code, err = run([loop, "--op-range", "0,100", "--columns", "t=OP", *FAST], capsys)
    assert code == 2 and "its default column 'OP' is mapped to t" in err
    huge = tmp_path / "huge.csv"
    huge.write_text("\n".join([lines[0]] + [",".join(c if j < 2 else f"{float(c) * 1e20:.6e}" for j, c in
                                                     enumerate(r.split(","))) for r in lines[1:]]) + "\n")
    code, err = run([huge, "--op-range", "0,100", *FAST], capsys)
    assert code == 2 and "'PV' (pv), 'SP' (sp) have no usable value" in err and "beyond 1e15" in err
