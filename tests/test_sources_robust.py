"""Fleet mode's loop discovery and loading on awkward historian exports (valve_gym/fleet/sources.py).

Duplicated tag columns, status texts in number columns, a mode column that toggles, a folder of
subfolders, and local time stamps across the daylight-saving fall-back. The loader functions are
called directly (no Ray).
"""
from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from valve_gym.diagnosis.recording import RecordingError, load_recording
from valve_gym.fleet.sources import discover_loops, load_loop


def _export(n=600, dt=1.0, start="2024-03-01 00:00:00", tags=("FIC101",)):
    """A wide export: a timestamp column and, per tag, TAG.PV, TAG.OP [%], TAG.SP."""
    t = pd.date_range(start, periods=n, freq=pd.Timedelta(seconds=dt))
    df = pd.DataFrame({"timestamp": t.strftime("%Y-%m-%d %H:%M:%S")})
    k = np.arange(n)
    for j, tag in enumerate(tags):
        df[f"{tag}.PV"] = 2.0 + np.sin(2 * np.pi * k / (60 + 7 * j)) + 0.01 * np.cos(k)
        df[f"{tag}.OP"] = 50.0 + 20.0 * np.sin(2 * np.pi * k / (60 + 7 * j) + 0.5)
        df[f"{tag}.SP"] = 2.0
    return df


def _parquet_with_names(df: pd.DataFrame, names: list[str], path) -> None:
    """``df`` written as Parquet under ``names`` (which may repeat a name; pandas refuses that)."""
    pq.write_table(pa.table([pa.array(df.iloc[:, i]) for i in range(df.shape[1])], names=names), path)


# --------------------------------------------------------------------------- duplicated columns
@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_a_duplicated_tag_column_refuses_that_tag_only(tmp_path, fmt):
    df = _export(tags=("FIC101", "LIC202"))
    df["dup"] = 99.0                                  # a second FIC101.PV holding other values
    names = list(df.columns[:-1]) + ["FIC101.PV"]
    p = tmp_path / f"export.{fmt}"
    if fmt == "csv":
        df.to_csv(p, index=False, header=names)
    else:
        _parquet_with_names(df, names, p)
    srcs = {s.name: s for s in discover_loops(str(p))}
    bad, good = srcs["FIC101"], srcs["LIC202"]
    assert bad.kind == "bad" and good.kind == "wide"
    assert "column 'FIC101.PV' appears 2 times (columns 2, 8 of the header)" in bad.problem
    assert "delete or rename the duplicate column" in bad.problem
    with pytest.raises(RecordingError, match=r"tag 'FIC101': column 'FIC101\.PV' appears 2 times"):
        load_loop(bad, op_range=(0, 100))
    assert len(load_loop(good, op_range=(0, 100)).recording) == 600     # the other tag is read


def test_two_spellings_of_one_role_and_a_duplicated_time_column(tmp_path):
    df = _export()
    df["FIC101.pv"] = df["FIC101.PV"] + 1.0
    p = tmp_path / "case.csv"
    df.to_csv(p, index=False)
    (src,) = discover_loops(str(p))
    assert src.kind == "bad" and "columns 'FIC101.PV' and 'FIC101.pv' both name its PV" in src.problem
    df = _export(tags=("FIC101", "LIC202"))
    names = list(df.columns) + ["timestamp"]
    df["t2"] = df["timestamp"]
    p = tmp_path / "time.csv"
    df.to_csv(p, index=False, header=names)
    srcs = discover_loops(str(p))
    assert [s.kind for s in srcs] == ["bad", "bad"]
    assert all("the time-stamp column 'timestamp' appears 2 times (columns 1, 8 of the header)" in s.problem
               for s in srcs)


# --------------------------------------------------------------------------- status texts
def test_a_few_status_texts_are_missing_samples_named_in_a_note(tmp_path):
    df = _export()
    df["FIC101.PV"] = df["FIC101.PV"].astype(object)
    df.loc[[100, 101], "FIC101.PV"] = "Bad Input"
    p = tmp_path / "export.csv"
    df.to_csv(p, index=False)
    (src,) = discover_loops(str(p))
    rec = load_loop(src, op_range=(0, 100)).recording
    assert len(rec) == 600
    note = next(n for n in rec.repairs if "not numbers" in n)
    assert note.startswith("column 'FIC101.PV': 2 cell(s) that are not numbers (first 'Bad Input' at row 101, "
                           "timestamp 2024-03-01 00:01:40): read as missing samples")
    clean = _export()["FIC101.PV"].to_numpy(dtype=float)
    assert np.all(np.isfinite(rec.pv)) and np.abs(rec.pv[100:102] - clean[100:102]).max() < 0.15  # bridged


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_a_column_of_mostly_text_is_refused_naming_the_first_cell(tmp_path, fmt):
    df = _export()
    df["FIC101.OP"] = df["FIC101.OP"].astype(str)
    df.loc[40:, "FIC101.OP"] = "Comm Fail"
    p = tmp_path / f"export.{fmt}"
    df.to_csv(p, index=False) if fmt == "csv" else df.to_parquet(p, index=False)
    (src,) = discover_loops(str(p))
    with pytest.raises(RecordingError) as e:
        load_loop(src, op_range=(0, 100))
    assert (f"{p}: column 'FIC101.OP' of tag 'FIC101': 560 of its 600 filled cells are not numbers (first "
            f"'Comm Fail' at row 41, timestamp 2024-03-01 00:00:40); the column holds text") in str(e.value)


def test_a_status_text_in_the_time_column_drops_that_row_with_a_note(tmp_path):
    df = _export()
    df.loc[200, "timestamp"] = "Bad Input"
    p = tmp_path / "export.csv"
    df.to_csv(p, index=False)
    (src,) = discover_loops(str(p))
    loaded = load_loop(src, op_range=(0, 100))
    assert len(loaded.recording) == 600 and loaded.gaps == ()
    assert any(n.startswith("column 'timestamp': 1 cell(s) that are neither numbers nor dates (first 'Bad Input' "
                            "at row 201): the rows without a time stamp are not read") for n in loaded.notes)


# --------------------------------------------------------------------------- mode
def test_a_mode_that_toggles_every_sample_says_so(tmp_path):
    df = _export()
    df["FIC101.MODE"] = ["AUTO" if i % 2 else "MAN" for i in range(len(df))]
    p = tmp_path / "export.csv"
    df.to_csv(p, index=False)
    (src,) = discover_loops(str(p))
    with pytest.raises(RecordingError) as e:
        load_loop(src, op_range=(0, 100))
    msg = str(e.value)
    assert "usable samples" not in msg
    assert ("column 'FIC101.MODE' (mode): the mode changes between automatic and manual 599 times in 600 samples, "
            "and the longest automatic stretch is 1 sample(s)") in msg
    assert "check the mode column and its coding" in msg and "--columns mode=" in msg
    rec = load_loop(src, columns={"mode": None}, op_range=(0, 100)).recording    # the option it names
    assert len(rec) == 600 and not any("MODE" in n for n in rec.repairs) and rec.sp is not None
    assert load_loop(src, columns={"mode": None, "sp": None}, op_range=(0, 100)).recording.sp is None


# --------------------------------------------------------------------------- folders
def test_a_folder_of_subfolders_names_them(tmp_path):
    for area in ("area1", "area2"):
        (tmp_path / area).mkdir()
    _export().to_csv(tmp_path / "area2" / "export.csv", index=False)
    with pytest.raises(RecordingError) as e:
        discover_loops(str(tmp_path))
    msg = str(e.value)
    assert "holds 2 subfolder(s) (area1, area2)" in msg
    assert "fleet mode reads only the files directly in the folder given" in msg
    assert f"give one subfolder (e.g. {str(tmp_path / 'area2')!r}, which holds recordings)" in msg


# --------------------------------------------------------------------------- daylight saving
def _fall_back(tmp_path, aware: bool):
    """Local stamps every 10 s from 01:00 to 03:30 on 27 October 2024 (CET/CEST): 02:00-02:59 twice."""
    df = _export(n=900, dt=10.0, tags=("FIC101",))
    utc = pd.date_range("2024-10-26 23:00:00", periods=900, freq=pd.Timedelta(seconds=10), tz="UTC")
    local = utc.tz_convert("Europe/Berlin")
    df["timestamp"] = [str(x) if aware else x.strftime("%Y-%m-%d %H:%M:%S") for x in local]
    p = tmp_path / f"export_{'aware' if aware else 'naive'}.csv"
    df.to_csv(p, index=False)
    return p


def test_the_daylight_saving_fall_back_is_refused_like_a_single_recording(tmp_path):
    p = _fall_back(tmp_path, aware=False)
    (src,) = discover_loops(str(p))
    with pytest.raises(RecordingError) as fleet:
        load_loop(src, op_range=(0, 100))
    msg = str(fleet.value)
    assert msg.startswith(f"{p}: column 'timestamp' (t): time stamps decrease 1 time(s), first at row 721 "
                          f"(2024-10-27 02:59:50 -> 2024-10-27 02:00:00); the clock goes back 3590 s")
    assert "daylight-saving fall-back" in msg and "export the time stamps in UTC or with their UTC offset" in msg
    with pytest.raises(RecordingError) as single:           # the one-recording loader: the same words
        load_recording(p, columns={"t": "timestamp", "op": "FIC101.OP", "pv": "FIC101.PV", "sp": "FIC101.SP"},
                       op_range=(0, 100))
    assert re.sub(r"(row|line) \d+", "N", msg) == re.sub(r"(row|line) \d+", "N", str(single.value))


def test_the_same_stamps_with_their_utc_offset_load_whole(tmp_path):
    (src,) = discover_loops(str(_fall_back(tmp_path, aware=True)))
    loaded = load_loop(src, op_range=(0, 100))
    assert len(loaded.recording) == 900 and loaded.gaps == () and loaded.recording.dt == 10.0


def test_a_single_recording_with_a_duplicated_tag_column_is_refused(tmp_path):
    """The single-file loader took the first of two ``FIC101.PV`` columns without a word."""
    df = _export()
    df["dup"] = 99.0
    p = tmp_path / "one.csv"
    df.to_csv(p, index=False, header=list(df.columns[:-1]) + ["FIC101.PV"])
    with pytest.raises(RecordingError, match=r"column 'FIC101\.PV' appears 2 times \(columns 2, 5 of the header\)"):
        load_recording(str(p), op_range=(0, 100))
    # naming the column to use is the way out the message gives; without the duplicate the file loads
    df.drop(columns="dup").to_csv(p, index=False)
    assert len(load_recording(str(p), op_range=(0, 100))) == 600


def test_rows_repeating_a_time_stamp_with_another_value_are_named():
    """Two values at one time stamp: the first is kept, and the notes say so (it was dropped without a word)."""
    from valve_gym.fleet.sources import resample_loop

    t = np.arange(200.0)
    pv, op = np.sin(t / 9.0), np.cos(t / 9.0)
    t2, pv2, op2 = np.insert(t, 51, 50.0), np.insert(pv, 51, 5.0), np.insert(op, 51, op[50])
    grid, values, gaps, notes = resample_loop(t2, {"pv": pv2, "op": op2})
    assert len(grid) == 200 and values["pv"][50] == pv[50] and not gaps
    said = [n for n in notes if "repeat the time stamp" in n]
    assert len(said) == 1 and said[0].startswith("PV: 1 row(s)") and "at 50 s" in said[0]
    assert not any("repeat" in n for n in resample_loop(np.insert(t, 51, 50.0), {"pv": np.insert(pv, 51, pv[50]),
                                                                                   "op": op2})[3])
