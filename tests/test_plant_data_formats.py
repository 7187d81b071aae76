"""Plant data as historians give it, without flags: the output's scale and the time stamps read from the data."""
from __future__ import annotations

import csv
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from valve_gym.diagnosis.recording import RecordingError, load_recording
from valve_gym.diagnosis.recording.units import infer_op_range, numeric_time_unit, parse_stamps


def _loop(n: int = 300, seed: int = 0):
    """A small PI loop on a first-order process (OP fraction 0..1, PV around 0)."""
    rng = np.random.default_rng(seed)
    op = 0.5 + 0.1 * np.sin(np.arange(n) / 9.0) + 0.01 * rng.standard_normal(n)
    pv = np.zeros(n)
    for k in range(1, n):
        pv[k] = 0.9 * pv[k - 1] + 0.1 * 3.0 * (op[k - 1] - 0.5) + 0.002 * rng.standard_normal()
    return op, pv


def _write(path, header, rows):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    return path


@pytest.mark.parametrize("values, rng, word", [
    ([48.5, 54.2], (0.0, 100.0), "percent"),
    ([-2.0, 103.0], (0.0, 100.0), "percent"),             # a controller's -5..105 % limits
    ([0.2, 0.7], (0.0, 1.0), "fraction"),
    ([-3.0, 2.5], (-3.0, 2.5), "unknown"),                  # deviation units
    ([120.0, 480.0], (120.0, 480.0), "unknown"),            # engineering units (kg/h)
])
def test_op_range_read_from_the_values(values, rng, word):
    got, note = infer_op_range(np.array(values))
    assert got == rng and word in note


@pytest.mark.parametrize("scale", [1.0, 100.0])
def test_op_percent_and_fraction_read_the_same(tmp_path, scale):
    op, pv = _loop()
    p = _write(tmp_path / "loop.csv", ["t", "OP", "PV"], zip(np.arange(len(op)), scale * op, pv))
    rec = load_recording(p)
    np.testing.assert_allclose(rec.op, op, rtol=1e-9)
    assert any(("percent" if scale == 100 else "fraction") in n for n in rec.notes)


def test_deviation_units_and_negative_pv(tmp_path):
    op, pv = _loop()
    p = _write(tmp_path / "dev.csv", ["t", "OP", "PV"], zip(np.arange(len(op)), 40 * (op - 0.5), pv - 7.0))
    rec = load_recording(p)
    assert rec.op.min() == 0.0 and rec.op.max() == 1.0 and rec.pv.min() < 0
    assert any("OP span unknown" in n for n in rec.notes)


def _stamps(fmt: str, n: int, start=datetime(2024, 7, 3, 23, 50), step=10):
    return [(start + timedelta(seconds=step * k)).strftime(fmt) for k in range(n)]


@pytest.mark.parametrize("fmt, word", [
    ("%d/%m/%y %H:%M:%S", "day-first"),                     # 03/07/24 23:50:00 ... 04/07/24: ambiguous, regular
    ("%m/%d/%Y %I:%M:%S %p", "month-first"),                # 07/03/2024 11:50:00 PM, 12-hour clock
    ("%d-%b-%Y %H:%M:%S", "month names"),
    ("%Y-%m-%d %H:%M:%S", None),                            # ISO
])
def test_date_formats_are_read(tmp_path, fmt, word):
    op, pv = _loop(n=200)
    p = _write(tmp_path / "d.csv", ["timestamp", "OP", "PV"], zip(_stamps(fmt, 200), 100 * op, pv))
    rec = load_recording(p)
    assert rec.dt == 10.0 and len(rec) == 200
    assert rec.start is not None
    if word:
        assert any(word in n for n in rec.notes)


def test_day_first_read_from_a_field_above_12(tmp_path):
    op, pv = _loop(n=100)
    stamps = _stamps("%d/%m/%y %H:%M", 100, start=datetime(2024, 7, 18, 0, 35), step=60)    # 18/07/24 0:35
    rec = load_recording(_write(tmp_path / "d.csv", ["time", "OP", "PV"], zip(stamps, 100 * op, pv)))
    assert rec.dt == 60.0 and any("day-first" in n and "above 12" in n for n in rec.notes)


def test_ambiguous_dates_ask_for_dayfirst_in_one_line():
    # 1, 2, 3 February read day-first, or 2 January, 2 February, 2 March month-first: both near-regular
    cells = [f"0{d}/02/2024 00:00" for d in range(1, 4)]
    with pytest.raises(RecordingError, match="--dayfirst or --monthfirst") as e:
        parse_stamps(cells, range(len(cells)))
    assert "\n" not in str(e.value)
    sec, bad, note = parse_stamps(cells, range(len(cells)), dayfirst=True)
    assert not bad and np.allclose(np.diff(sec), 86400.0) and note is not None and "as given" in note
    sec_m, _, _ = parse_stamps(cells, range(len(cells)), dayfirst=False)
    assert np.allclose(np.diff(sec_m), [31 * 86400.0, 29 * 86400.0])


def test_a_regular_interval_decides_ambiguous_dates():
    # 10-minute samples across midnight between 2 and 3 April 2024: only day-first gives a regular step
    start = datetime(2024, 4, 2, 23, 0)
    cells = _stamps("%d/%m/%Y %H:%M", 12, start=start, step=600)
    sec, _, note = parse_stamps(cells, range(12))
    assert np.allclose(np.diff(sec), 600.0) and note is not None and "day-first" in note and "regular" in note


@pytest.mark.parametrize("factor, unit", [(1.0, "epoch seconds"), (1000.0, "epoch milliseconds")])
def test_epoch_time_columns(tmp_path, factor, unit):
    op, pv = _loop(n=150)
    t0 = datetime(2024, 7, 3, tzinfo=timezone.utc).timestamp()
    t = (t0 + 5.0 * np.arange(150)) * factor
    rec = load_recording(_write(tmp_path / "e.csv", ["t", "OP", "PV"],
                                ([f"{a:.0f}", b, c] for a, b, c in zip(t, 100 * op, pv))))
    assert rec.dt == 5.0 and rec.start == "2024-07-03 00:00:00"
    assert any(unit in n for n in rec.notes)


def test_spreadsheet_serial_days_and_the_override():
    t = 45476.0 + np.arange(100) * 10.0 / 86400.0
    f, epoch0, note = numeric_time_unit(t)
    assert f == 86400.0 and note is not None and "serial days" in note
    assert epoch0 is not None and abs(epoch0 - datetime(2024, 7, 3, tzinfo=timezone.utc).timestamp()) < 1
    f, _, note = numeric_time_unit(t, "s")                   # --time-unit s: seconds as written
    assert f == 1.0


def test_gaps_are_kept_out_by_default_with_a_note(tmp_path):
    op, pv = _loop(n=300)
    pv_cells = [f"{v:.6g}" for v in pv]
    for k in range(100, 120):
        pv_cells[k] = ""
    rec = load_recording(_write(tmp_path / "g.csv", ["t", "OP", "PV"], zip(range(300), 100 * op, pv_cells)))
    assert len(rec) == 180 and any("longest stretch" in r for r in rec.repairs)
    with pytest.raises(RecordingError, match="gap"):
        load_recording(tmp_path / "g.csv", gaps="error")


def test_wide_export_in_percent_without_flags(tmp_path):
    """A historian's wide export (OP in percent, day-first stamps) gives a full table and worklist, no flags."""
    import pandas as pd

    from valve_gym.fleet import FleetSettings
    from valve_gym.fleet.analyse import analyse_loop
    from valve_gym.fleet.simulate import simulate_loop
    from valve_gym.fleet.sources import discover_loops
    from valve_gym.fleet.table import write_table
    from valve_gym.fleet.worklist import write_worklist

    n = 500
    start = datetime(2024, 7, 18, 0, 35)
    df = pd.DataFrame({"Time": _stamps("%d/%m/%Y %H:%M:%S", n, start=start, step=1)})
    for tag, kind, seed in (("FIC101", "healthy", 1), ("LIC202", "disturbance", 2), ("PIC303", "sticky", 3)):
        loop = simulate_loop(kind, seed=seed, n=n).recording
        df[f"{tag}.PV"] = 1000.0 * loop.pv - 250.0           # PV in its own units, negative values included
        df[f"{tag}.OP"] = 100 * loop.op
        assert loop.sp is not None
        df[f"{tag}.SP"] = 1000.0 * loop.sp - 250.0
    p = tmp_path / "export.csv"
    df.to_csv(p, index=False)
    settings = FleetSettings(effort="fast", candidates=())   # no --op-range, no --plant, no date order
    srcs = discover_loops(str(p))
    results = [analyse_loop(s, settings, s.name) for s in srcs]
    assert [r.status for r in results] == ["ok"] * 3, [r.message for r in results]
    assert all(any("OP read in percent" in n for n in r.notes) for r in results)
    assert all(any("day-first" in n for n in r.notes) for r in results)
    out = tmp_path / "out"
    out.mkdir()
    table, csv_path = write_table(results, str(out))
    md, html = write_worklist(results, srcs, str(out), settings, top=0)
    text = open(md, encoding="utf-8").read()
    rows = list(csv.DictReader(open(csv_path, encoding="utf-8")))
    assert len(rows) == 3 and {"cause", "p_valve", "p_tuning", "p_disturbance"} <= set(rows[0])
    assert "cause (p valve / tuning / disturbance / sensor / saturation)" in text
    assert "could not be analysed" not in text
