"""Bad input to the recording loader: historian bad-value codes, an output already a fraction read with a
percent range, a loop-mode cut that leaves too few rows, one column for two roles, and the Python API's
argument forms (a columns string, an open file, a range string)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from valve_gym.diagnosis import cli
from valve_gym.diagnosis.recording import Recording, RecordingError, load_recording


def loop(n=400, seed=0):
    """A loop: op in percent (square wave), pv a first-order response around 0.7..0.9, set point."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    op = 40 + 10 * np.sign(np.sin(2 * np.pi * t / 40)) + 0.2 * rng.normal(size=n)
    pv = np.zeros(n)
    pv[0] = 0.8
    for k in range(1, n):
        pv[k] = 0.9 * pv[k - 1] + 0.1 * (0.8 + (op[k - 1] - 40) / 100)
    sp = np.where(t < n / 2, 0.8, 0.85)
    return t, op, pv, sp


def write(path, header, cols):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(zip(*cols))
    return path


# --------------------------------------------------------------------------
# 1. historian bad-value codes
# --------------------------------------------------------------------------


@pytest.mark.parametrize("code", [-9999.0, -999.0, 9999.0, -1e30])
def test_isolated_bad_value_code_is_a_stated_repair(tmp_path, code):
    t, op, pv, sp = loop()
    bad = pv.copy()
    bad[100] = code
    bad[250:252] = code                                        # a run of two
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP"], [t, op, bad, sp])
    rec = load_recording(p, op_range=(0, 100))
    assert len(rec) == 400 and 0.6 < rec.pv.min() and rec.pv.max() < 1.0
    np.testing.assert_allclose(rec.pv[100], 0.5 * (pv[99] + pv[101]))
    np.testing.assert_allclose(rec.pv[250:252], pv[249] + (pv[252] - pv[249]) * np.array([1, 2]) / 3)
    said = [r for r in rec.repairs if "absurd value(s) of 'PV' (pv)" in r]
    assert len(said) == 1
    assert "3 absurd value(s)" in said[0] and "line(s) 102, 252, 253" in said[0]
    assert f"({code:g})" in said[0] and "historian's bad-value code" in said[0]
    if abs(code) < 1e15:
        assert "times the span of the other values" in said[0]
    assert any("filled" in r and "'PV'" in r for r in rec.repairs)


def test_bad_value_code_in_op_and_sp_columns(tmp_path):
    t, op, pv, sp = loop()
    op_b, sp_b = op.copy(), sp.copy()
    op_b[30] = -9999
    sp_b[[10, 300]] = 9999
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP"], [t, op_b, pv, sp_b])
    rec = load_recording(p, op_range=(0, 100))
    assert rec.op.min() > 0.25 and rec.sp is not None and rec.sp.max() == pytest.approx(0.85)
    assert any("1 absurd value(s) of 'OP' (op) at line(s) 32 (-9999)" in r for r in rec.repairs)
    assert any("2 absurd value(s) of 'SP' (sp) at line(s) 12, 302 (9999)" in r for r in rec.repairs)


def test_an_output_inside_its_range_is_never_a_bad_value_code(tmp_path):
    """An output that saturates for two samples is data: inside --op-range it is not read as a code."""
    t, op, pv, sp = loop()
    kick = 41.0 + 0.5 * np.sin(t / 30.0)                      # an output moving 40.5..41.5 % ...
    kick[150:152] = 100.0                                     # ... that hits 100 % for two samples
    kick[300] = -9999.0                                       # and a bad-value code
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP"], [t, kick, pv, sp])
    rec = load_recording(p, op_range=(0, 100))
    assert np.all(rec.op[150:152] == 1.0)
    assert any("1 absurd value(s) of 'OP' (op) at line(s) 302 (-9999)" in r for r in rec.repairs)


def test_genuine_excursion_is_kept(tmp_path):
    """A few samples a few times the normal span outside it are process data, not a bad-value code."""
    t, op, pv, sp = loop()
    odd = pv.copy()
    odd[100] = 1.5                                             # ~3.5 spans above the range of the others
    odd[200:203] = 0.0                                         # ~4 spans below it, three samples
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP"], [t, op, odd, sp])
    rec = load_recording(p, op_range=(0, 100))
    assert rec.pv[100] == 1.5 and np.all(rec.pv[200:203] == 0.0)
    assert not any("absurd" in r for r in rec.repairs)


def test_long_run_of_an_unknown_far_value_is_not_a_spike(tmp_path):
    """Past SPIKE_SAMPLES samples in a row the spike rule does not read a code (as the relative spike rule)."""
    t, op, pv, sp = loop()
    odd = pv.copy()
    odd[100:104] = -8888
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP"], [t, op, odd, sp])
    rec = load_recording(p, op_range=(0, 100))
    assert rec.pv.min() == -8888 and not any("absurd" in r for r in rec.repairs)


def test_a_known_code_in_a_long_run_is_an_outage(tmp_path):
    """-9999 written for a stretch (a transmitter outage) is missing data: a short one filled, a long one a gap."""
    t, op, pv, sp = loop()
    short, long_ = pv.copy(), pv.copy()
    short[100:104] = -9999                                    # 4 samples: within the default max_gap of 5
    long_[100:130] = -9999                                    # 30 samples: a gap
    rec = load_recording(write(tmp_path / "s.csv", ["t", "OP", "PV", "SP"], [t, op, short, sp]), op_range=(0, 100))
    assert rec.pv.min() > 0.5 and np.allclose(rec.pv[100:104], np.interp(np.arange(100, 104), [99, 104],
                                                                          [pv[99], pv[104]]))
    assert any("4 absurd value(s) of 'PV' (pv)" in r and "a known bad-value code" in r for r in rec.repairs)
    p = write(tmp_path / "l.csv", ["t", "OP", "PV", "SP"], [t, op, long_, sp])
    with pytest.raises(RecordingError, match="gap"):
        load_recording(p, op_range=(0, 100), gaps="error")
    kept = load_recording(p, op_range=(0, 100), gaps="longest")
    assert kept.pv.min() > 0.5 and len(kept) == 270                 # the 270 samples after the outage


def test_a_known_code_inside_the_range_of_the_others_is_data(tmp_path):
    """9999 in a signal that runs 9990..10010 is a value like the others."""
    t, op, pv, sp = loop()
    big = 10000.0 + 10.0 * (pv - pv.mean()) / np.ptp(pv)
    big[50:60] = 9999.0
    rec = load_recording(write(tmp_path / "b.csv", ["t", "OP", "PV", "SP"], [t, op, big, sp]), op_range=(0, 100))
    assert np.all(rec.pv[50:60] == 9999.0) and not any("absurd" in r for r in rec.repairs)


def test_frequent_short_pulses_are_part_of_the_range(tmp_path):
    """Far values in more than SENTINEL_FRACTION of the rows (here short pulses in 2.5 % of them) are part of
    the column's range, not a few bad-value codes: kept as they are."""
    t, op, pv, sp = loop()
    odd = pv.copy()
    odd[::40] = 30.0
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP"], [t, op, odd, sp])
    rec = load_recording(p, op_range=(0, 100))
    assert np.all(rec.pv[::40] == 30.0) and not any("absurd" in r for r in rec.repairs)


# --------------------------------------------------------------------------
# 2. an output already a fraction, read with a percent range
# --------------------------------------------------------------------------


def test_fraction_op_with_percent_range_is_refused(tmp_path):
    t, op, pv, sp = loop()
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP"], [t, op / 100, pv, sp])
    with pytest.raises(RecordingError) as e:
        load_recording(p, op_range=(0, 100))
    msg = str(e.value)
    assert msg.startswith(f"{p}: column 'OP' (op): all OP values lie in 0..1 (")
    assert ("at most 1 % of --op-range 0,100: the output looks like a fraction already; leave out --op-range "
            "(or give --op-range 0,1" in msg)
    with pytest.raises(RecordingError, match=r"at most 1 % of --op-range 0,100"):
        load_recording(p, op_range="0,100")
    # the same file without the range, or with 0..1, loads
    assert load_recording(p).op_range == (0.0, 1.0)
    np.testing.assert_allclose(load_recording(p, op_range=(0, 1)).op, op / 100, atol=1e-12)
    # a small range (0..10 V) is not a percent: values in 0..1 are 10 % of it, allowed
    assert load_recording(p, op_range=(0, 10)).op_range == (0.0, 10.0)


def test_fraction_stem_position_with_percent_range_is_refused(tmp_path):
    t, op, pv, sp = loop()
    mv = np.clip(op / 100 + 0.01, 0, 1)
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP", "stem"], [t, op, pv, sp, mv])
    with pytest.raises(RecordingError, match=r"column 'stem' \(mv\): all MV values lie in 0\.\.1 .*--op-range 0,100 "
                                             r"\(the stem position's range when --mv-range is left out\).*"
                                             r"give --mv-range 0,1"):
        load_recording(p, op_range=(0, 100))
    rec = load_recording(p, op_range=(0, 100), mv_range=(0, 1))
    assert rec.mv is not None and rec.mv.max() > 0.5


def test_fraction_op_refused_by_the_cli(tmp_path, capsys):
    t, op, pv, sp = loop()
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP"], [t, op / 100, pv, sp])
    code = cli.main([str(p), "--op-range", "0,100", "--effects", "none", "--effort", "fast", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert "the output looks like a fraction already; leave out --op-range (or give --op-range 0,1" in err


# --------------------------------------------------------------------------
# 3. the loop-mode cut leaves too few rows
# --------------------------------------------------------------------------


def test_mode_cut_too_short_names_the_mode_column(tmp_path):
    t, op, pv, sp = loop()
    mode = ["MAN"] * 400
    mode[100:140] = ["AUTO"] * 40
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP", "MODE"], [t, op, pv, sp, mode])
    with pytest.raises(RecordingError) as e:
        load_recording(p, op_range=(0, 100))
    msg = str(e.value)
    assert msg.startswith(f"{p}: column 'MODE' (mode): the loop mode leaves only 40 of the 400 data rows")
    assert "the longest automatic stretch is lines 102-141" in msg
    assert "at least 50 samples" in msg and "only 40 data rows" not in msg
    assert "export a longer stretch in automatic, or pass --columns mode=" in msg
    # the advice works: the whole record is read
    rec = load_recording(p, op_range=(0, 100), columns="mode=")
    assert len(rec) == 400 and "mode" not in rec.columns


# --------------------------------------------------------------------------
# 4. one column for two roles
# --------------------------------------------------------------------------


@pytest.mark.parametrize("columns,given,role", [({"pv": "SP"}, "pv", "sp"), ({"op": "stem"}, "op", "mv"),
                                                ({"pv": "MODE"}, "pv", "mode"), ({"t": "SP"}, "t", "sp")])
def test_a_column_serves_one_role_only(tmp_path, columns, given, role):
    t, op, pv, sp = loop()
    mv = np.clip(op / 100, 0, 1) * 100
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP", "stem", "MODE"], [t, op, pv, sp, mv, ["AUTO"] * 400])
    col = columns[given]
    with pytest.raises(RecordingError) as e:
        load_recording(p, columns=columns, op_range=(0, 100))
    msg = str(e.value)
    assert f"column {col!r} is given for {given} " in msg and "one column may serve one role only" in msg
    assert f"({role}); " in msg and f"--columns {role}=" in msg


def test_column_for_two_roles_refused_by_the_cli(tmp_path, capsys):
    t, op, pv, sp = loop()
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP"], [t, op, pv, sp])
    code = cli.main([str(p), "--op-range", "0,100", "--columns", "pv=SP", "--effects", "none",
                     "--effort", "fast", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert "column 'SP' is given for pv (process variable) but by its name holds the set point (sp)" in err
    # switching the set point off, as the message says, is accepted
    rec = load_recording(p, columns={"pv": "SP", "sp": None}, op_range=(0, 100))
    assert rec.sp is None and rec.columns["pv"] == "SP"


def test_tagged_column_serves_one_role_only(tmp_path):
    t, op, pv, sp = loop()
    p = write(tmp_path / "x.csv", ["t", "FIC1.OP", "FIC1.PV", "FIC1.SP"], [t, op, pv, sp])
    with pytest.raises(RecordingError, match=r"column 'FIC1\.SP' is given for pv .* holds the set point \(sp\)"):
        load_recording(p, columns={"pv": "FIC1.SP"}, op_range=(0, 100))


# --------------------------------------------------------------------------
# 5. Python API argument forms
# --------------------------------------------------------------------------


def test_columns_as_the_cli_string(tmp_path):
    t, op, pv, sp = loop()
    p = write(tmp_path / "x.csv", ["time_x", "A", "B", "C"], [t, op, pv, sp])
    rec = load_recording(p, columns="t=time_x, op=A, pv=B, sp=C", op_range=(0, 100))
    assert rec.columns == {"t": "time_x", "op": "A", "pv": "B", "sp": "C"}
    with pytest.raises(RecordingError, match=r"columns: column mapping item 'op' has no '='"):
        load_recording(p, columns="op", op_range=(0, 100))
    with pytest.raises(RecordingError, match=r"columns must be a dict of role to column name like "
                                             r"\{'op': 'OP', 'pv': 'PV'\}.*got list"):
        load_recording(p, columns=["op", "A"], op_range=(0, 100))  # type: ignore[arg-type]


def test_open_file_is_refused_clearly(tmp_path):
    t, op, pv, sp = loop()
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP"], [t, op, pv, sp])
    with open(p) as f, pytest.raises(RecordingError, match=r"pass the file's path .*not an open file"):
        load_recording(f, op_range=(0, 100))  # type: ignore[arg-type]
    with pytest.raises(RecordingError, match=r"pass the file's path .*not a int"):
        load_recording(3, op_range=(0, 100))  # type: ignore[arg-type]
    assert len(load_recording(str(p).encode(), op_range=(0, 100))) == 400


def test_range_strings():
    t = np.arange(5.0)
    with pytest.raises(ValueError, match=r"Recording\.op_range must be a pair of numbers \(lo, hi\), "
                                         r"e\.g\. \(0, 100\), got '0,100'"):
        Recording(t=t, op=t / 10, pv=t, op_range="0,100")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"Recording\.op_range must be a pair of numbers"):
        Recording(t=t, op=t / 10, pv=t, op_range=(0, 100, 5))  # type: ignore[arg-type]
    assert Recording(t=t, op=t / 10, pv=t, op_range=(0, 100)).op_range == (0.0, 100.0)


def test_range_strings_in_load_recording(tmp_path):
    t, op, pv, sp = loop()
    p = write(tmp_path / "x.csv", ["t", "OP", "PV", "SP", "stem"], [t, op, pv, sp, op])
    rec = load_recording(p, op_range="0,100", mv_range="0,100")
    assert rec.op_range == (0.0, 100.0) and rec.mv is not None
    with pytest.raises(RecordingError, match=r"e\.g\. --mv-range 0,100"):
        load_recording(p, op_range="0,100", mv_range="0;100")
