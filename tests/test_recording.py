"""Tests of valve_gym.diagnosis.recording: shipped data and every bad-input case."""

from __future__ import annotations

import csv
import doctest

import numpy as np
import pytest

from valve_gym.diagnosis import recording as recmod
from valve_gym.diagnosis.recording import (
    MIN_SAMPLES,
    Recording,
    RecordingError,
    data_path,
    load_recording,
    parse_columns,
    parse_range,
)

# --------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------


def signals(n=200, dt=1.0):
    """A plausible loop: op in percent (square wave), pv first-order response."""
    t = np.arange(n) * dt
    op = 40 + 10 * np.sign(np.sin(2 * np.pi * t / (40 * dt)))
    pv = np.zeros(n)
    for k in range(1, n):
        pv[k] = 0.9 * pv[k - 1] + 0.1 * op[k - 1]
    return t, op, pv


def write_csv(path, header, rows):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    return path


def write_loop(tmp_path, t=None, op=None, pv=None, name="loop.csv", **kw):
    t0, op0, pv0 = signals(**kw)
    t = t0 if t is None else t
    op = op0 if op is None else op
    pv = pv0 if pv is None else pv
    rows = [[a, b, c] for a, b, c in zip(t, op, pv)]
    return write_csv(tmp_path / name, ["t", "op", "pv"], rows)


# --------------------------------------------------------------------------
# shipped data
# --------------------------------------------------------------------------


def test_cascaded_tanks():
    rec = load_recording(
        data_path("cascaded_tanks/estimation.csv"),
        columns={"t": "t_s", "op": "u_V", "pv": "y_V"},
        op_range=(0, 10),
    )
    assert len(rec) == 1024
    assert rec.dt == 4.0
    assert rec.repairs == ()
    assert rec.sp is None and rec.mv is None
    assert rec.op_range == (0.0, 10.0)
    assert rec.columns == {"t": "t_s", "op": "u_V", "pv": "y_V"}
    assert rec.t.dtype == np.float64 and rec.op.shape == (1024,)
    assert 0.04 < rec.op.min() < rec.op.max() < 0.65
    assert rec.pv.max() == pytest.approx(10.0)  # sensor saturation at 10 V
    # default column names find the same columns
    rec2 = load_recording(data_path("cascaded_tanks/estimation.csv"), op_range=(0, 10))
    assert rec2.columns == rec.columns
    np.testing.assert_array_equal(rec2.op, rec.op)


def test_stictiongpt_record():
    path = data_path("stictiongpt_plant_loops/csv/stiction__2411FIC20102_0609_0957.csv")
    rec = load_recording(
        path, columns={"t": "t_s", "op": "OP", "pv": "PV", "sp": "SP"}, op_range=(0, 100)
    )
    assert len(rec) == 751 and rec.dt == 10.0 and rec.repairs == ()
    assert rec.sp is not None and rec.sp.shape == (751,)
    assert 0 < rec.op.min() < rec.op.max() < 1
    assert rec.name == "stiction__2411FIC20102_0609_0957"


def test_stictiongpt_all_records_match_index():
    import pandas as pd

    root = data_path("stictiongpt_plant_loops")
    index = pd.read_csv(root / "index.csv")
    assert len(index) == 49
    assert sorted(index["expert_label"].unique()) == ["no_stiction", "stiction"]
    for row in index.itertuples():
        rec = load_recording(root / row.csv_file, op_range=(0, 100))
        assert len(rec) == row.n_samples
        assert rec.dt == row.Ts_s
        assert rec.columns == {"t": "t_s", "op": "OP", "pv": "PV", "sp": "SP"}


def test_npokhappy_iso_timestamps():
    rec = load_recording(
        data_path("npokhappy_factory/LIC-106_sorted.csv"),
        columns={"t": "timestamp", "op": "OP_level_valve_LV106", "pv": "flow_FT115"},
        op_range=(0, 100),
    )
    assert len(rec) == 10080 and rec.dt == 60.0
    assert rec.t[0] == 0.0 and rec.t[-1] == 60.0 * 10079
    assert rec.start == "2024-11-21 00:00:00"


def test_npokhappy_long_gap_and_longest():
    path = data_path("npokhappy_factory/FIC-211_sorted.csv")
    cols = {"t": "timestamp", "op": "OP_valve_FV211", "pv": "PV_flow_FT211"}
    with pytest.raises(RecordingError, match=r"gap.*64 missing samples.*PV_flow_FT211"):
        load_recording(path, columns=cols, op_range=(0, 100), gaps="error")
    rec = load_recording(path, columns=cols, op_range=(0, 100))           # the default keeps the longest stretch
    assert len(rec) == 6585
    assert any("longest stretch" in r for r in rec.repairs)
    assert any("filled 3 missing" in r for r in rec.repairs)


def test_data_path_missing():
    with pytest.raises(FileNotFoundError, match="no shipped data file.*cascaded_tanks"):
        data_path("no_such_dataset/x.csv")
    with pytest.raises(FileNotFoundError, match="estimation.csv"):
        data_path("cascaded_tanks/nope.csv")


def test_doctests():
    res = doctest.testmod(recmod)
    assert res.attempted > 0 and res.failed == 0


# --------------------------------------------------------------------------
# Recording object
# --------------------------------------------------------------------------


def test_recording_methods(tmp_path):
    rec = load_recording(write_loop(tmp_path), op_range=(0, 100), name="demo")
    assert len(rec) == 200 and rec.name == "demo"
    part = rec.slice(10, 60)
    assert isinstance(part, Recording) and len(part) == 50
    assert part.t[0] == rec.t[10] and part.dt == rec.dt
    assert len(rec.slice(-20, None)) == 20
    with pytest.raises(ValueError, match="empty"):
        rec.slice(5, 5)
    df = rec.to_dataframe()
    assert list(df.columns) == ["t", "op", "pv"] and len(df) == 200
    assert df.attrs["dt"] == 1.0
    with pytest.raises(ValueError):
        rec.op[0] = 0.5  # read-only
    with pytest.raises(AttributeError):
        rec.dt = 2.0  # frozen
    assert "demo" in repr(rec)


def test_with_op_lag_pairs_each_op_with_the_next_pv():
    t = np.arange(6.0)
    rec = Recording(t=t, op=np.linspace(0.1, 0.6, 6), pv=t * 10, sp=t * 100, mv=np.linspace(0.0, 0.5, 6),
                    name="r")
    assert rec.with_op_lag(0) is rec
    sh = rec.with_op_lag(1)
    assert len(sh) == 5 and sh.dt == rec.dt and sh.name == "r"
    np.testing.assert_array_equal(sh.op, rec.op[:-1])
    for k in ("t", "pv", "sp", "mv"):                      # measured (or read) with the PV: they stay with it
        np.testing.assert_array_equal(getattr(sh, k), getattr(rec, k)[1:])
    assert "op[k-1] with pv[k]" in sh.notes[-1]
    for bad in (2, -1, True, 0.5):
        with pytest.raises(ValueError, match="op lag must be 0 or 1"):
            rec.with_op_lag(bad)
    with pytest.raises(ValueError, match="at least 3"):
        rec.slice(0, 2).with_op_lag(1)


def test_recording_validates():
    t = np.arange(10.0)
    with pytest.raises(ValueError, match="normalised"):
        Recording(t=t, op=np.full(10, 2.0), pv=t)
    with pytest.raises(ValueError, match="NaN"):
        Recording(t=t, op=np.full(10, np.nan), pv=t)
    with pytest.raises(ValueError, match="uniformly"):
        Recording(t=t**2, op=np.zeros(10), pv=t)
    assert Recording(t=t, op=np.zeros(10), pv=t).dt == 1.0


# --------------------------------------------------------------------------
# CLI helpers
# --------------------------------------------------------------------------


def test_parse_columns():
    assert parse_columns("t=t_s,op=OP,pv=PV") == {"t": "t_s", "op": "OP", "pv": "PV"}
    assert parse_columns(" sp = ,mv=Stem ") == {"sp": None, "mv": "Stem"}
    with pytest.raises(RecordingError, match="no '='"):
        parse_columns("t_s,OP")
    with pytest.raises(RecordingError, match="unknown role 'xx'"):
        parse_columns("xx=a")
    with pytest.raises(RecordingError, match="given twice"):
        parse_columns("t=a,t=b")
    with pytest.raises(RecordingError, match="needs a column name"):
        parse_columns("pv=")
    with pytest.raises(RecordingError, match="empty"):
        parse_columns("  ")


def test_parse_range():
    assert parse_range("0,100") == (0.0, 100.0)
    assert parse_range(" -1.5 , 2 ") == (-1.5, 2.0)
    for bad, msg in [("0", "not two"), ("0,1,2", "not two"), ("a,1", "non-number"),
                     ("0,inf", "finite"), ("5,5", "LO >= HI")]:
        with pytest.raises(RecordingError, match=msg):
            parse_range(bad)


# --------------------------------------------------------------------------
# bad inputs
# --------------------------------------------------------------------------


def test_file_missing(tmp_path):
    with pytest.raises(RecordingError, match="nope.csv: file not found"):
        load_recording(tmp_path / "nope.csv")


def test_path_is_folder(tmp_path):
    with pytest.raises(RecordingError, match="is a folder"):
        load_recording(tmp_path)


def test_empty_file(tmp_path):
    (tmp_path / "e.csv").write_text("")
    with pytest.raises(RecordingError, match="e.csv: file is empty"):
        load_recording(tmp_path / "e.csv")


def test_binary_file(tmp_path):
    (tmp_path / "b.xlsx").write_bytes(b"PK\x03\x04\x00\x00binary")
    with pytest.raises(RecordingError, match="not a text CSV file"):
        load_recording(tmp_path / "b.xlsx")


def test_not_csv_one_column(tmp_path):
    (tmp_path / "x.txt").write_text("hello world\nthis is prose\n")
    with pytest.raises(RecordingError, match="only one column"):
        load_recording(tmp_path / "x.txt")


def test_ragged_rows(tmp_path):
    p = write_loop(tmp_path)
    with open(p, "a") as f:
        f.write("1000,50\n")
    with pytest.raises(RecordingError, match=r"lines 202 have a different number of fields"):
        load_recording(p, op_range=(0, 100))


def test_named_column_absent(tmp_path):
    p = write_loop(tmp_path)
    with pytest.raises(RecordingError, match=r"column 'PV_X' given for the process variable \(pv\) "
                                             r"is not in the file; available columns: 't', 'op', 'pv'"):
        load_recording(p, columns={"pv": "PV_X"}, op_range=(0, 100))


def test_default_column_not_found(tmp_path):
    t, op, pv = signals()
    p = write_csv(tmp_path / "odd.csv", ["time", "valve_cmd", "pv"], zip(t, op, pv))
    with pytest.raises(RecordingError, match=r"no column for the controller output \(op\).*--columns op=NAME"):
        load_recording(p, op_range=(0, 100))
    rec = load_recording(p, columns={"op": "VALVE_CMD"}, op_range=(0, 100))  # case-insensitive
    assert rec.columns["op"] == "valve_cmd"


def test_one_loops_tag_prefixed_columns_are_read(tmp_path):
    """A historian's export of one loop (``TAG.OP``, ``TAG.PV``, ``TAG.SP``) needs no --columns; several tags,
    or signals of different tags, are refused with a message that names them and the way out."""
    t, op, pv = signals()
    p = write_csv(tmp_path / "loop.csv", ["timestamp", "FIC101.OP", "FIC101.PV", "FIC101.SP"],
                  zip(t, op, pv, pv))
    rec = load_recording(p, op_range=(0, 100))
    assert rec.columns["op"] == "FIC101.OP" and rec.columns["pv"] == "FIC101.PV" and rec.columns["sp"] == "FIC101.SP"
    np.testing.assert_allclose(rec.pv, pv)
    p2 = write_csv(tmp_path / "two.csv", ["t", "FIC101.OP", "FIC101.PV", "LIC7.OP", "LIC7.PV"],
                   zip(t, op, pv, op, pv))
    with pytest.raises(RecordingError, match=r"several loops' controller output \(FIC101, LIC7\).*--out OUTDIR"):
        load_recording(p2, op_range=(0, 100))
    p3 = write_csv(tmp_path / "mixed.csv", ["t", "FIC101.OP", "LIC7.PV"], zip(t, op, pv))
    with pytest.raises(RecordingError, match=r"different tags \(op from 'FIC101.OP', pv from 'LIC7.PV'\)"):
        load_recording(p3, op_range=(0, 100))
    p4 = write_csv(tmp_path / "named.csv", ["t", "op", "FIC101.PV", "FIC102.PV"], zip(t, op, pv, pv))
    with pytest.raises(RecordingError, match=r"several loops' process variable \(FIC101, FIC102\)"):
        load_recording(p4, op_range=(0, 100))
    assert load_recording(p4, columns={"pv": "FIC102.PV"}, op_range=(0, 100)).columns["pv"] == "FIC102.PV"


@pytest.mark.parametrize("engine", ["rows", "columns"])
def test_loop_mode_column_keeps_the_longest_automatic_stretch(tmp_path, engine):
    """A ``TAG.MODE`` (or ``mode``) column: the manual rows are cut off, the longest automatic stretch
    is kept and the repair names the column and the file lines; a blank cell holds the mode above it."""
    t, op, pv = signals(n=300)
    mode = ["AUTO"] * 300
    mode[60:100] = ["MAN"] * 40
    mode[101:] = [""] * 199                       # stored on change: AUTO from line 103 on
    p = write_csv(tmp_path / "FIC101.csv", ["t", "FIC101.OP", "FIC101.PV", "FIC101.MODE"],
                  zip(t, op, pv, mode))
    rec = load_recording(p, op_range=(0, 100), engine=engine)
    assert len(rec) == 200
    np.testing.assert_allclose(rec.pv, pv[100:])
    np.testing.assert_allclose(rec.t, t[100:])          # the times of the file
    assert rec.repairs == ("column 'FIC101.MODE': MODE manual in 40 of 300 samples: kept the longest automatic "
                           "stretch, lines 102-301 of the file",)
    assert "mode" not in rec.columns
    # switched off: the whole record, as before
    whole = load_recording(p, op_range=(0, 100), columns={"mode": ""}, engine=engine)
    assert len(whole) == 300 and whole.repairs == ()


def test_loop_mode_column_manual_throughout_and_unknown_codes(tmp_path):
    t, op, pv = signals(n=200)
    p = write_csv(tmp_path / "man.csv", ["t", "op", "pv", "mode"], zip(t, op, pv, ["MAN"] * 200))
    with pytest.raises(RecordingError, match=r"column 'mode': the loop is in manual throughout.*--columns mode="):
        load_recording(p, op_range=(0, 100))
    # a code the table does not know is kept (read as automatic) and named, never dropped on a guess
    p2 = write_csv(tmp_path / "codes.csv", ["t", "op", "pv", "mode"],
                   zip(t, op, pv, [1] * 100 + [2] * 100))
    rec = load_recording(p2, op_range=(0, 100))
    assert len(rec) == 200
    assert rec.repairs == ("column 'mode': MODE value(s) 2 not among the manual modes (0, 0.0, FALSE, IMAN, LO, M, "
                           "MAN, MANUAL, OOS): read as automatic",)
    # numeric codes 1 (automatic) and 0 (manual), as the labelled plant loops' exports write them
    p3 = write_csv(tmp_path / "num.csv", ["t", "op", "pv", "mode"], zip(t, op, pv, [0] * 30 + [1] * 170))
    assert len(load_recording(p3, op_range=(0, 100))) == 170


def test_unknown_role(tmp_path):
    with pytest.raises(RecordingError, match="unknown role 'flow'"):
        load_recording(write_loop(tmp_path), columns={"flow": "pv"})


def test_non_numeric_cells(tmp_path):
    t, op, pv = signals()
    pv = pv.astype(object)
    pv[3] = "bad"
    pv[7] = "1,5"
    p = write_csv(tmp_path / "n.csv", ["t", "op", "pv"], zip(t, op, pv))
    with pytest.raises(RecordingError, match=r"n.csv: column 'pv' \(pv\): 2 non-numeric cell\(s\) "
                                             r"at line\(s\) 5, 9 \(e.g. 'bad'\)"):
        load_recording(p, op_range=(0, 100))


def test_short_gap_repaired(tmp_path):
    t, op, pv = signals()
    pv_bad = pv.astype(object)
    pv_bad[50:53] = ""
    p = write_csv(tmp_path / "g.csv", ["t", "op", "pv"], zip(t, op, pv_bad))
    rec = load_recording(p, op_range=(0, 100))
    assert len(rec) == 200
    assert np.all(np.isfinite(rec.pv))
    np.testing.assert_allclose(rec.pv[50:53], np.interp([50, 51, 52], [49, 53], pv[[49, 53]]))
    assert any("filled 3 missing value(s) in 'pv'" in r for r in rec.repairs)


def test_long_gap_error_and_longest(tmp_path):
    t, op, pv = signals()
    pv = pv.astype(object)
    pv[60:70] = "nan"
    p = write_csv(tmp_path / "g.csv", ["t", "op", "pv"], zip(t, op, pv))
    with pytest.raises(RecordingError, match=r"longer than max_gap=5.*10 missing samples between "
                                             r"t=59 s and t=70 s in 'pv'"):
        load_recording(p, op_range=(0, 100), gaps="error")
    rec = load_recording(p, op_range=(0, 100), max_gap=10)
    assert len(rec) == 200
    rec = load_recording(p, op_range=(0, 100), gaps="longest")
    assert len(rec) == 130 and rec.t[0] == 70.0
    assert any("longest stretch" in r for r in rec.repairs)


def test_edge_missing_trimmed(tmp_path):
    t, op, pv = signals()
    op = op.astype(object)
    op[:4] = ""
    p = write_csv(tmp_path / "e.csv", ["t", "op", "pv"], zip(t, op, pv))
    rec = load_recording(p, op_range=(0, 100))
    assert len(rec) == 196 and rec.t[0] == 4.0
    assert any("dropped 4 leading" in r for r in rec.repairs)


def test_constant_op(tmp_path):
    p = write_loop(tmp_path, op=np.full(200, 42.0))
    with pytest.raises(RecordingError, match=r"column 'op' \(op\): the controller output is constant"):
        load_recording(p, op_range=(0, 100))


def test_constant_pv(tmp_path):
    p = write_loop(tmp_path, pv=np.full(200, 3.0))
    with pytest.raises(RecordingError, match=r"column 'pv' \(pv\): the process variable is constant"):
        load_recording(p, op_range=(0, 100))


def test_too_short(tmp_path):
    p = write_loop(tmp_path, n=MIN_SAMPLES - 1)
    with pytest.raises(RecordingError, match=r"only 49 data rows.*at least 50"):
        load_recording(p, op_range=(0, 100))


def test_decreasing_time(tmp_path):
    t, op, pv = signals()
    t = t.copy()
    t[[100, 101]] = t[[101, 100]]
    p = write_loop(tmp_path, t=t)
    with pytest.raises(RecordingError, match=r"column 't' \(t\): time stamps decrease 1 time\(s\), first at line 103"):
        load_recording(p, op_range=(0, 100))


def test_descending_file(tmp_path):
    t, op, pv = signals()
    p = write_loop(tmp_path, t=t[::-1].copy())
    with pytest.raises(RecordingError, match="descending time order; sort it"):
        load_recording(p, op_range=(0, 100))


def test_duplicate_time_different_values(tmp_path):
    t, op, pv = signals()
    rows = [[a, b, c] for a, b, c in zip(t, op, pv)]
    rows.insert(51, [t[50], op[50], pv[50] + 1.0])
    p = write_csv(tmp_path / "d.csv", ["t", "op", "pv"], rows)
    with pytest.raises(RecordingError, match=r"duplicate time stamp\(s\) with different values \(lines 52 and 53\)"):
        load_recording(p, op_range=(0, 100))


def test_exact_duplicate_rows_dropped(tmp_path):
    t, op, pv = signals()
    rows = [[a, b, c] for a, b, c in zip(t, op, pv)]
    rows.insert(51, list(rows[50]))
    p = write_csv(tmp_path / "d.csv", ["t", "op", "pv"], rows)
    rec = load_recording(p, op_range=(0, 100))
    assert len(rec) == 200
    assert any("dropped 1 exact duplicate row" in r for r in rec.repairs)


def test_missing_time_stamp(tmp_path):
    t, op, pv = signals()
    t = t.astype(object)
    t[10] = ""
    p = write_loop(tmp_path, t=t)
    with pytest.raises(RecordingError, match=r"1 missing time stamp\(s\) at line\(s\) 12"):
        load_recording(p, op_range=(0, 100))


def test_small_jitter_resampled(tmp_path):
    t, op, pv = signals()
    rng = np.random.default_rng(0)
    tj = t + rng.uniform(-0.04, 0.04, t.size)
    tj[0], tj[-1] = 0.0, t[-1]
    p = write_loop(tmp_path, t=tj)
    rec = load_recording(p, op_range=(0, 100))
    assert rec.dt == pytest.approx(1.0, abs=0.02)
    assert np.allclose(np.diff(rec.t), rec.dt)
    assert any("small time-stamp jitter" in r and "zero-order hold" in r for r in rec.repairs)
    # op is held, so it only takes values present in the file
    assert set(np.round(rec.op * 100, 9)) <= set(np.round(op, 9))
    # still resampled with resample=False: jitter < 10 %
    assert load_recording(p, op_range=(0, 100), resample=False).repairs == rec.repairs


def test_large_irregular_sampling(tmp_path):
    t, op, pv = signals()
    rng = np.random.default_rng(1)
    tj = np.cumsum(rng.uniform(0.6, 1.4, t.size))
    p = write_loop(tmp_path, t=tj)
    with pytest.raises(RecordingError, match=r"irregular sampling.*resample='auto'"):
        load_recording(p, op_range=(0, 100), resample=False)
    rec = load_recording(p, op_range=(0, 100))
    assert any("irregular sampling" in r for r in rec.repairs)
    assert np.allclose(np.diff(rec.t), rec.dt)


def test_missing_rows_short_and_long(tmp_path):
    t, op, pv = signals()
    keep = np.ones(t.size, bool)
    keep[80:83] = False  # three rows absent: time jumps 79 -> 83
    p = write_loop(tmp_path, t=t[keep], op=op[keep], pv=pv[keep])
    rec = load_recording(p, op_range=(0, 100))
    assert len(rec) == 200 and rec.dt == 1.0
    assert any("3 missing sample(s) inserted" in r for r in rec.repairs)
    keep[80:100] = False
    p = write_loop(tmp_path, t=t[keep], op=op[keep], pv=pv[keep], name="long.csv")
    with pytest.raises(RecordingError, match=r"20 missing samples between t=79 s and t=100 s: no rows in the file"):
        load_recording(p, op_range=(0, 100), gaps="error")


def test_op_range_read_from_values(tmp_path):
    """An output in 30..50 without --op-range is read in percent, and the choice is a note."""
    rec = load_recording(write_loop(tmp_path))
    given = load_recording(write_loop(tmp_path), op_range=(0, 100))
    assert rec.op_range == (0.0, 100.0)
    np.testing.assert_array_equal(rec.op, given.op)
    assert any("OP read in percent" in n for n in rec.notes)


def test_op_slightly_outside_clipped(tmp_path):
    t, op, pv = signals()
    op = op.copy()
    op[5] = 101.0
    op[6] = -2.0
    rec = load_recording(write_loop(tmp_path, op=op), op_range=(0, 100))
    assert rec.op.max() == 1.0 and rec.op.min() == 0.0
    assert any("clipped 2 value(s) of 'op'" in r for r in rec.repairs)


def test_op_far_outside_range(tmp_path):
    with pytest.raises(RecordingError, match=r"more than 5 % of the span outside the range 0\.\.10"):
        load_recording(write_loop(tmp_path), op_range=(0, 10))


def test_bad_options(tmp_path):
    p = write_loop(tmp_path)
    with pytest.raises(RecordingError, match="max_gap"):
        load_recording(p, op_range=(0, 100), max_gap=-1)
    with pytest.raises(RecordingError, match="gaps must be"):
        load_recording(p, op_range=(0, 100), gaps="split")
    with pytest.raises(RecordingError, match="op_range must be"):
        load_recording(p, op_range=(100, 0))


def test_sp_mv_and_semicolon_bom(tmp_path):
    t, op, pv = signals()
    stem = op * 0.98
    text = "\ufeffTime;CO;PV;Setpoint;Stem\n" + "".join(
        f"{a};{b};{c};20;{d}\n" for a, b, c, d in zip(t, op, pv, stem)
    )
    (tmp_path / "s.csv").write_text(text, encoding="utf-8")
    rec = load_recording(tmp_path / "s.csv", op_range="0,100")
    assert rec.columns == {"t": "Time", "op": "CO", "pv": "PV", "sp": "Setpoint", "mv": "Stem"}
    np.testing.assert_allclose(rec.mv, stem / 100)
    assert np.all(rec.sp == 20)
    rec = load_recording(tmp_path / "s.csv", op_range=(0, 100), columns={"sp": None, "mv": None})
    assert rec.sp is None and rec.mv is None


def test_iso_timestamps(tmp_path):
    t, op, pv = signals()
    stamps = [f"2024-03-01T10:{int(s) // 60:02d}:{int(s) % 60:02d}" for s in t]
    p = write_csv(tmp_path / "iso.csv", ["timestamp", "op", "pv"], zip(stamps, op, pv))
    rec = load_recording(p, op_range=(0, 100))
    np.testing.assert_array_equal(rec.t, t)
    assert rec.start == "2024-03-01T10:00:00"
    stamps[7] = "yesterday"
    p = write_csv(tmp_path / "iso2.csv", ["timestamp", "op", "pv"], zip(stamps, op, pv))
    with pytest.raises(RecordingError, match=r"neither numbers \(seconds\) nor dates, at line\(s\) 9"):
        load_recording(p, op_range=(0, 100))


# --------------------------------------------------------------------------
# non-finite and absurd values, time axis extremes
# --------------------------------------------------------------------------


@pytest.mark.parametrize("engine", ["rows", "columns"])
@pytest.mark.parametrize("cell,kind", [("inf", "non-finite"), ("-inf", "non-finite"), ("1e309", "non-finite"),
                                       ("1e308", "absurd"), ("-3.4e38", "absurd")])
def test_non_finite_and_absurd_values_repaired(tmp_path, engine, cell, kind):
    t, op, pv = signals()
    bad = pv.astype(object)
    bad[100] = cell
    p = write_csv(tmp_path / "x.csv", ["t", "op", "pv"], zip(t, op, bad))
    rec = load_recording(p, op_range=(0, 100), engine=engine)
    assert len(rec) == 200 and np.all(np.isfinite(rec.pv))
    np.testing.assert_allclose(rec.pv[100], 0.5 * (pv[99] + pv[101]))
    assert any(f"{kind} value(s)" in r and "'pv' (pv) at line(s) 102" in r for r in rec.repairs)
    assert any("filled 1 missing value(s) in 'pv'" in r for r in rec.repairs)


def test_absurd_spike_relative_rule(tmp_path):
    t, op, pv = signals()
    bad = pv.copy()
    bad[60:62] = 3e9  # two samples, 1e8 times the signal's size: a spike of an error code
    rec = load_recording(write_loop(tmp_path, pv=bad), op_range=(0, 100))
    assert rec.pv.max() < 60
    assert any("absurd value(s) of 'pv'" in r and "line(s) 62, 63" in r for r in rec.repairs)
    # a long plateau at a huge but finite level is data, not a spike: no repair, no error
    odd = pv.copy()
    odd[60:160] += 1e9
    rec = load_recording(write_loop(tmp_path, pv=odd, name="odd.csv"), op_range=(0, 100))
    assert rec.pv.max() > 1e9 and not any("absurd" in r for r in rec.repairs)


def test_long_run_of_absurd_values_is_a_gap_error(tmp_path):
    t, op, pv = signals()
    bad = pv.copy()
    bad[80:90] = 1e30
    with pytest.raises(RecordingError, match=r"longer than max_gap=5.*10 missing samples between t=79 s "
                                             r"and t=90 s in 'pv'"):
        load_recording(write_loop(tmp_path, pv=bad), op_range=(0, 100), gaps="error")


def test_non_finite_time_stamp(tmp_path):
    t, op, pv = signals()
    tt = t.astype(object)
    tt[50] = "inf"
    with pytest.raises(RecordingError, match=r"column 't' \(t\): 1 non-finite time stamp\(s\).*line\(s\) 52"):
        load_recording(write_loop(tmp_path, t=tt), op_range=(0, 100))


def test_absurd_time_jump(tmp_path):
    t, op, pv = signals()
    tt = t.copy()
    tt[-1] = 1e308
    p = write_loop(tmp_path, t=tt)
    with pytest.raises(RecordingError, match=r"mostly gaps.*line 201: t=198 s to t=1e\+308 s.*gaps='longest'"):
        load_recording(p, op_range=(0, 100), gaps="error")
    rec = load_recording(p, op_range=(0, 100), gaps="longest")
    assert len(rec) == 199 and rec.t[-1] == 198.0
    assert any("longest stretch" in r and "1 jump(s)" in r for r in rec.repairs)


def test_op_far_outside_names_time(tmp_path):
    t, op, pv = signals()
    op = op.copy()
    op[120] = 400.0
    with pytest.raises(RecordingError, match=r"outside the range 0\.\.100 \(1 sample\(s\), first at t=120 s: 400\)"):
        load_recording(write_loop(tmp_path, op=op), op_range=(0, 100))


def test_header_only(tmp_path):
    (tmp_path / "h.csv").write_text("t,op,pv\n")
    for engine in ("rows", "columns"):
        with pytest.raises(RecordingError, match="no data rows"):
            load_recording(tmp_path / "h.csv", engine=engine)


def test_all_missing_column(tmp_path):
    t, op, pv = signals()
    p = write_csv(tmp_path / "m.csv", ["t", "op", "pv"], zip(t, op, ["nan"] * len(t)))
    with pytest.raises(RecordingError, match=r"column 'pv' \(pv\): has no numeric values at all"):
        load_recording(p, op_range=(0, 100))


def test_bad_new_options(tmp_path):
    p = write_loop(tmp_path)
    with pytest.raises(RecordingError, match="max_samples must be"):
        load_recording(p, op_range=(0, 100), max_samples=3)
    with pytest.raises(RecordingError, match="engine must be one of"):
        load_recording(p, op_range=(0, 100), engine="fast")
    with pytest.raises(RecordingError, match="op_range must be finite"):
        load_recording(p, op_range=(-1e308, 1e308))


# --------------------------------------------------------------------------
# the column-wise reader gives the same recording as the row reader
# --------------------------------------------------------------------------


def test_columnwise_reader_matches_rows(tmp_path):
    t, op, pv = signals()
    pvb = pv.astype(object)
    pvb[50:53] = ""
    text = "\ufeffTime;CO;PV;Setpoint\n" + "".join(f"{a};{b};{c};20\n" for a, b, c in zip(t, op, pvb))
    text = text.replace("\n10;", "\n\n10;")  # a blank line before t=10
    (tmp_path / "s.csv").write_text(text, encoding="utf-8")
    a = load_recording(tmp_path / "s.csv", op_range=(0, 100), engine="rows")
    b = load_recording(tmp_path / "s.csv", op_range=(0, 100), engine="columns")
    assert a.columns == b.columns and a.repairs == b.repairs
    for r in ("t", "op", "pv", "sp"):
        np.testing.assert_array_equal(getattr(a, r), getattr(b, r))
    assert any("column-wise" in n for n in b.notes) and a.notes == ()


def test_columnwise_reader_messages(tmp_path):
    t, op, pv = signals()
    pvb = pv.astype(object)
    pvb[3] = "bad"
    p = write_csv(tmp_path / "n.csv", ["t", "op", "pv"], zip(t, op, pvb))
    with pytest.raises(RecordingError, match=r"1 non-numeric cell\(s\) at line\(s\) 5 \(e.g. 'bad'\)"):
        load_recording(p, op_range=(0, 100), engine="columns")
    p = write_loop(tmp_path)
    with open(p, "a") as f:
        f.write('200,"50,1\n201,50,1\n')
    with pytest.raises(RecordingError, match=r"not a valid CSV file \(.*EOF inside string.*\)"):
        load_recording(p, op_range=(0, 100), engine="columns")


# --------------------------------------------------------------------------
# Parquet
# --------------------------------------------------------------------------


def _parquet(path, **cols):
    import pandas as pd

    pd.DataFrame(cols).to_parquet(path)
    return path


def test_parquet_numeric_and_csv_agree(tmp_path):
    t, op, pv = signals()
    p = _parquet(tmp_path / "loop.parquet", t=t, op=op, pv=pv)
    rec = load_recording(p, op_range=(0, 100))
    ref = load_recording(write_loop(tmp_path), op_range=(0, 100))
    np.testing.assert_array_equal(rec.pv, ref.pv)
    np.testing.assert_array_equal(rec.op, ref.op)
    assert rec.name == "loop" and rec.repairs == () and "Parquet" in rec.notes[0]


def test_parquet_timestamps_nulls_and_bad_cells(tmp_path):
    import pandas as pd

    t, op, pv = signals()
    stamps = pd.date_range("2024-03-01 10:00:00", periods=len(t), freq="1s")
    pvn = pv.copy()
    pvn[10] = np.nan
    rec = load_recording(_parquet(tmp_path / "a.parquet", timestamp=stamps, op=op, pv=pvn), op_range=(0, 100))
    np.testing.assert_array_equal(rec.t, t)
    assert rec.start == "2024-03-01 10:00:00"
    assert any("filled 1 missing value(s) in 'pv'" in r for r in rec.repairs)
    txt = pv.astype(str).astype(object)
    txt[20] = "oops"
    with pytest.raises(RecordingError, match=r"b.parquet: column 'pv' \(pv\): 1 non-numeric cell\(s\) at row\(s\) 21"):
        load_recording(_parquet(tmp_path / "b.parquet", t=t, op=op, pv=txt), op_range=(0, 100))


def test_parquet_bad_files(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    (tmp_path / "c.parquet").write_bytes(b"PAR1 not really")
    with pytest.raises(RecordingError, match="not a readable Parquet file"):
        load_recording(tmp_path / "c.parquet")
    t, op, pv = signals()
    table = pa.table({"t": t, "op": op, "pv": pa.array([[x] for x in pv])})
    pq.write_table(table, tmp_path / "l.parquet")
    with pytest.raises(RecordingError, match=r"column 'pv' has the Parquet type list<.*expected numbers"):
        load_recording(tmp_path / "l.parquet", op_range=(0, 100))
    pq.write_table(pa.table({"t": pa.array([], pa.float64()), "op": pa.array([], pa.float64()),
                             "pv": pa.array([], pa.float64())}), tmp_path / "e.parquet")
    with pytest.raises(RecordingError, match="no data rows"):
        load_recording(tmp_path / "e.parquet")


# --------------------------------------------------------------------------
# long records: decimation to the dominant time scale, window
# --------------------------------------------------------------------------


def _slow_loop(n, dt, T=30.0, seed=0):
    """First-order response (time constant T seconds) to a random square-wave op, with noise."""
    rng = np.random.default_rng(seed)
    hold = int(round(4 * T / dt))
    levels = rng.uniform(20, 80, n // hold + 1)
    op = np.repeat(levels, hold)[:n]
    a = np.exp(-dt / T)
    pv = np.empty(n)
    pv[0] = op[0]
    for k in range(1, n):
        pv[k] = a * pv[k - 1] + (1 - a) * op[k - 1]
    return np.arange(n) * dt, op, pv + rng.normal(0, 0.2, n)


def test_time_scale_first_order():
    from valve_gym.diagnosis.recording.decimate import time_scale

    t, op, pv = _slow_loop(40_000, 0.1, T=30.0)
    ts = time_scale(pv, 0.1)
    assert 30.0 < ts < 200.0  # pv follows held op levels (4 T long) through a lag of T
    rng = np.random.default_rng(1)
    assert time_scale(rng.normal(size=5000), 0.1) <= 0.2  # white noise: a sample or two


def test_long_record_decimated(tmp_path):
    t, op, pv = _slow_loop(60_000, 0.1, T=30.0)
    p = write_loop(tmp_path, t=t, op=op, pv=pv)
    rec = load_recording(p, op_range=(0, 100), max_samples=20_000)
    assert 2_000 <= len(rec) <= 20_000
    assert rec.dt > 0.1 and np.allclose(np.diff(rec.t), rec.dt)
    q = int(round(rec.dt / 0.1))
    np.testing.assert_allclose(rec.pv[:5], pv[: 5 * q].reshape(5, q).mean(axis=1))
    assert rec.t[0] == pytest.approx((q - 1) / 2 * 0.1)  # block centre
    assert any(r.startswith(f"decimated by {q} from dt=0.1 s") for r in rec.repairs)
    assert any("dominant time scale" in n for n in rec.notes)
    full = load_recording(p, op_range=(0, 100), max_samples=None)
    assert len(full) == 60_000 and full.repairs == ()


def test_long_fast_record_windowed(tmp_path):
    from valve_gym.diagnosis.recording import condition

    rng = np.random.default_rng(0)
    n = 30_000
    t = np.arange(n) * 1.0
    op = np.clip(0.5 + 0.01 * rng.normal(size=n), 0, 1)
    op[20_000:21_000] += 0.3 * np.sign(np.sin(np.arange(1000) / 20))  # the informative part
    pv = np.convolve(op, np.ones(3) / 3, mode="same") + 0.01 * rng.normal(size=n)
    t2, sig, cond = condition(t, {"op": op, "pv": pv}, 1.0, max_samples=5_000)
    assert cond is not None and cond.window is not None
    q = cond.factor  # as coarse as 8 samples per time scale allow, then the window
    assert q == max(1, int(cond.time_scale // 8)) and q < 30_000 / 5_000
    i0, i1 = cond.window
    assert i1 - i0 == 5_000 and len(t2) == 5_000 and i0 * q <= 20_000 and i1 * q >= 21_000
    assert any("most informative window" in s for s in cond.statements(float(t2[0])))
    assert condition(t, {"op": op, "pv": pv}, 1.0, max_samples=None)[2] is None


# --------------------------------------------------------------------------
# the parts alone
# --------------------------------------------------------------------------


def test_sniff_and_columns(tmp_path):
    from valve_gym.diagnosis.recording import resolve_columns
    from valve_gym.diagnosis.recording.sniff import sniff

    p = write_loop(tmp_path)
    sn = sniff(p)
    assert (sn.kind, sn.engine, sn.header, sn.header_line, sn.dialect.delimiter) == ("csv", "rows", ("t", "op", "pv"),
                                                                                     1, ",")
    assert sniff(p, engine="columns").engine == "columns"
    t, op, pv = signals()
    assert sniff(_parquet(tmp_path / "a.parquet", t=t, op=op, pv=pv)).kind == "parquet"
    cm = resolve_columns(["Time", "CO", "PV", "Stem"], {"mv": None}, "f")
    assert cm.index == {"t": 0, "op": 1, "pv": 2} and cm.names["op"] == "CO"
    assert cm.signal_roles == ["op", "pv"]
    with pytest.raises(RecordingError, match="used for both op and pv"):
        resolve_columns(["t", "a"], {"op": "a", "pv": "a"}, "f")


def test_recording_notes_roundtrip():
    t = np.arange(10.0)
    rec = Recording(t=t, op=np.zeros(10), pv=t, notes=["read somehow"])
    assert rec.notes == ("read somehow",)
    assert rec.slice(2, 5).notes == rec.notes and rec.to_dataframe().attrs["notes"] == ["read somehow"]


def test_parquet_invalid_utf8_text(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    t, op, pv = signals()
    bad = pa.Array.from_buffers(pa.binary(), 1, [None, pa.py_buffer(np.array([0, 2], np.int32).tobytes()),
                                                 pa.py_buffer(b"\xff\xfe")])
    texts = pa.concat_arrays([pa.array([str(v) for v in pv[:-1]], pa.binary()), bad]).cast(pa.string(), safe=False)
    pq.write_table(pa.table({"t": t, "op": op, "pv": texts}), tmp_path / "u.parquet")
    with pytest.raises(RecordingError, match=r"u.parquet: not a readable Parquet file \(.*utf-8"):
        load_recording(tmp_path / "u.parquet", op_range=(0, 100))
    with pytest.raises(RecordingError, match="given for the process variable"):  # mapping errors stay themselves
        load_recording(tmp_path / "u.parquet", op_range=(0, 100), columns={"pv": "nope"})


def test_wide_header_beyond_sniff_prefix(tmp_path):
    t, op, pv = signals()
    extra = [f"tag_{i:05d}" for i in range(7_000)]  # a header of 70 kB, longer than the sniffed prefix
    header = ",".join(["t", "op"] + extra + ["pv"])  # pv's name lies beyond the first 64 kB
    body = "".join(f"{a},{b}" + ",0" * len(extra) + f",{c}\n" for a, b, c in zip(t, op, pv))
    (tmp_path / "w.csv").write_text(header + "\n" + body)
    for engine in ("rows", "columns"):
        rec = load_recording(tmp_path / "w.csv", op_range=(0, 100), engine=engine)
        assert len(rec) == 200 and rec.columns == {"t": "t", "op": "op", "pv": "pv"}


def test_decimation_coarser_to_fit_the_budget():
    from scipy.signal import lfilter

    from valve_gym.diagnosis.recording import condition
    from valve_gym.diagnosis.recording.decimate import time_scale

    rng = np.random.default_rng(3)
    n, tau = 100_000, 100.0  # AR(1) signals with a 100 s time scale, sampled at 1 s
    a = np.exp(-1.0 / tau)
    op = lfilter([1 - a], [1, -a], rng.normal(size=n))
    pv = lfilter([1 - a], [1, -a], op) + 0.01 * rng.normal(size=n)
    scale = min(time_scale(op, 1.0), time_scale(pv, 1.0))
    assert 50 < scale < 200
    t2, sig, cond = condition(np.arange(n) * 1.0, {"op": op, "pv": pv}, 1.0, max_samples=12_000)
    # 20 samples per time scale would leave more than 12,000 samples; 8 per time scale allow fitting them all
    assert cond is not None and cond.window is None
    assert cond.factor == -(-n // 12_000) and len(t2) <= 12_000
    assert scale / cond.dt_out >= 8


# --------------------------------------------------------------------------
# DCS "PROCESSDATA" text exports (the format the labelled plant loops were exported in)
# --------------------------------------------------------------------------


def write_dcs_export(path, csv_path, tag="2411AIC90201", eol="\r\n", columns_engine=False, mode=None):
    """The shipped CSV record ``csv_path`` written as the plant's DCS export: a title line, the sampling
    line, the ``tagname`` line, a description line (UTF-8 Chinese text) and a parameter line, then
    tab-separated rows ``time stamp, TAG.MV, TAG.PV, TAG.SV, TAG.MODE, flags``."""
    import pandas as pd

    d = pd.read_csv(csv_path)
    cols = [f"{tag}.MV", f"{tag}.PV", f"{tag}.SV", f"{tag}.MODE", "bOpOFL", "bPvOFL", "bSpOFL", "bAutOFL"]
    lines = [f"PROCESSDATA\t{tag} Data\tyyyy-MM-dd HH:mm:ss",
             f"8\t10\t{d.timestamp.iloc[0]}\t{len(d)}",
             "tagname\t" + "\t".join(cols),
             "desc\t" + "\t".join(["分析仪_OP", "分析仪_PV", "分析仪_SP", "Aut", "bOpOFL", "bPvOFL", "bSpOFL",
                                   "bAutOFL"]),
             "fsMax=1.3\tfsMin=0\tfsGridNum=10\tL=24"]
    for i, r in enumerate(d.itertuples()):
        values = [repr(float(v)) for v in (r.OP, r.PV, r.SP)]
        lines.append("\t".join([r.timestamp] + values + ["1" if mode is None else str(mode[i]), "0", "0", "0", "0"]))
    path.write_bytes((eol.join(lines) + eol).encode("utf-8"))
    return path


def test_dcs_export_reads_like_its_csv(tmp_path):
    """A PROCESSDATA export is read as it comes: TAG.MV is the controller output, TAG.SV the set point, the
    description and parameter lines are skipped; same samples as the tidy CSV of the same record."""
    src = data_path("stictiongpt_plant_loops/csv/stiction__2411AIC90201_1002_0004.csv")
    txt = write_dcs_export(tmp_path / "stic_2411AIC90201.txt", src)
    sn = recmod.sniff.sniff(txt)
    assert sn.form == "dcs-export" and sn.header_line == 3 and sn.data_line == 6
    rec = load_recording(txt, op_range=(0, 100))
    ref = load_recording(src, op_range=(0, 100))
    assert rec.columns == {"t": "tagname", "op": "2411AIC90201.MV", "pv": "2411AIC90201.PV",
                           "sp": "2411AIC90201.SV"}
    assert len(rec) == len(ref) == 751 and rec.dt == ref.dt == 10.0 and rec.start == "2024-10-01 21:55:00"
    np.testing.assert_array_equal(rec.op, ref.op)
    np.testing.assert_array_equal(rec.pv, ref.pv)
    np.testing.assert_array_equal(rec.sp, ref.sp)
    # the column-wise reader of large files skips the same lines
    big = load_recording(txt, op_range=(0, 100), engine="columns")
    np.testing.assert_array_equal(big.op, ref.op)
    np.testing.assert_array_equal(big.pv, ref.pv)
    # the user's mapping wins over the format's
    own = load_recording(txt, op_range=(0, 100), columns={"sp": None})
    assert own.sp is None


def test_dcs_export_mode_zero_is_manual(tmp_path):
    """The export's ``TAG.MODE`` (1 automatic, as every shipped record; 0 manual) cuts a manual start off."""
    src = data_path("stictiongpt_plant_loops/csv/stiction__2411AIC90201_1002_0004.csv")
    txt = write_dcs_export(tmp_path / "stic_2411AIC90201.txt", src, mode=[0] * 100 + [1] * 651)
    rec = load_recording(txt, op_range=(0, 100))
    ref = load_recording(src, op_range=(0, 100))
    assert len(rec) == 651
    np.testing.assert_array_equal(rec.pv, ref.pv[100:])
    assert rec.repairs == ("column '2411AIC90201.MODE': MODE manual in 100 of 751 samples: kept the longest "
                           "automatic stretch, lines 106-756 of the file",)


def test_dcs_export_errors_name_the_problem(tmp_path):
    bad = tmp_path / "no_header.txt"
    bad.write_text("PROCESSDATA\tX Data\n8\t10\t2024-01-01 00:00:00\t3\n2024-01-01 00:00:00\t1\t2\t3\n")
    with pytest.raises(RecordingError, match="without its 'tagname' line"):
        load_recording(bad, op_range=(0, 100))
    empty = tmp_path / "no_rows.txt"
    empty.write_text("PROCESSDATA\tX Data\ntagname\tX.MV\tX.PV\ndesc\ta\tb\n")
    with pytest.raises(RecordingError, match="no data rows"):
        load_recording(empty, op_range=(0, 100))
    # two loops in one export: the roles cannot be guessed, the message says how to name them
    two = tmp_path / "two.txt"
    two.write_text("PROCESSDATA\tX Data\ntagname\tA.MV\tA.PV\tB.MV\tB.PV\n"
                   + "".join(f"2024-01-01 00:{k // 60:02d}:{k % 60:02d}\t{k % 7}\t{k % 5}\t1\t2\n" for k in range(80)))
    with pytest.raises(RecordingError, match="--columns"):
        load_recording(two, op_range=(0, 100))


def test_folders_pick_dcs_exports_not_other_text(tmp_path):
    from valve_gym.diagnosis.recording.sniff import is_dcs_export, recording_files
    from valve_gym.fleet.sources import discover_loops

    src = data_path("stictiongpt_plant_loops/csv/stiction__2411AIC90201_1002_0004.csv")
    write_dcs_export(tmp_path / "a.txt", src, eol="\n")
    (tmp_path / "README.txt").write_text("notes about these loops\n")
    write_loop(tmp_path, name="b.csv")
    assert is_dcs_export(tmp_path / "a.txt") and not is_dcs_export(tmp_path / "README.txt")
    assert [p.rsplit("/", 1)[-1] for p in recording_files(str(tmp_path))] == ["a.txt", "b.csv"]
    assert [s.name for s in discover_loops(str(tmp_path))] == ["a", "b"]


def test_decimal_comma_in_a_semicolon_file(tmp_path):
    """European exports: ';' between columns and a decimal comma in the numbers (time included)."""
    rng = np.random.default_rng(0)
    t = np.arange(300) * 0.5
    op = 0.5 + 0.1 * np.sin(t / 10) + 0.01 * rng.standard_normal(300)
    pv = 1.2 + 0.3 * np.sin(t / 10 - 0.5)
    p = tmp_path / "export.csv"
    p.write_text("Zeit;OP;PV\n" + "".join(f"{a:.1f};{b:.5f};{c:.5f}\n".replace(".", ",")
                                           for a, b, c in zip(t, op, pv)), encoding="utf-8")
    rec = load_recording(p, columns={"t": "Zeit", "op": "OP", "pv": "PV"})
    assert rec.dt == pytest.approx(0.5) and np.allclose(rec.op, op, atol=1e-5) and np.allclose(rec.pv, pv, atol=1e-5)
    assert any("decimal comma" in n for n in rec.notes)
    # a comma-separated file does not guess: a quoted "0,5" may be a thousands separator there
    q = tmp_path / "quoted.csv"
    cells = [f"{b:.3f}".replace(".", ",") for b in op]
    q.write_text("t,op,pv\n" + "".join(f'{a},"{b}",{c}\n' for a, b, c in zip(t, cells, pv)), encoding="utf-8")
    with pytest.raises(RecordingError, match="decimal comma is read only where the columns are separated"):
        load_recording(q)
