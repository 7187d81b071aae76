"""A file without a time column (a laboratory or MATLAB export) is read with its sample time: ``dt``/``--dt``."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from valve_gym.diagnosis import cli, load_recording
from valve_gym.diagnosis.recording import RecordingError
from valve_gym.diagnosis.synthetic import make_recording


@pytest.fixture(scope="module")
def untimed(tmp_path_factory):
    """The benchmark layout of the cascaded tanks: two records side by side, no time column, Ts in one cell."""
    rec = make_recording("none", seed=4, n=300)
    k = np.arange(len(rec.op))
    df = pd.DataFrame({"uEst": 100 * rec.op, "uVal": 100 * rec.op[::-1], "yEst": rec.pv, "yVal": rec.pv[::-1],
                       "Ts": np.where(k == 0, 2.0, np.nan)})
    p = tmp_path_factory.mktemp("dt") / "data.csv"
    df.to_csv(p, index=False)
    return p, rec


def test_the_rows_are_dt_apart_and_the_notes_say_so(untimed):
    p, rec = untimed
    r = load_recording(p, columns={"op": "uEst", "pv": "yEst"}, op_range=(0, 100), dt=2.0)
    assert r.dt == 2.0 and len(r) == len(rec.op) and np.allclose(r.t, 2.0 * np.arange(len(rec.op)))
    assert np.allclose(r.op, rec.op) and np.allclose(r.pv, rec.pv)
    assert r.columns["t"] == "row x 2 s" and any("row number x 2 s" in n for n in r.notes)
    other = load_recording(p, columns={"op": "uVal", "pv": "yVal", "t": ""}, op_range=(0, 100), dt=2.0)
    assert np.allclose(other.pv, rec.pv[::-1])                   # the validation record of the same file


def test_without_dt_the_message_says_how_to_read_it(untimed):
    p, _ = untimed
    with pytest.raises(RecordingError, match=r"no column for the time .*--dt SECONDS"):
        load_recording(p, columns={"op": "uEst", "pv": "yEst"}, op_range=(0, 100))
    with pytest.raises(RecordingError, match=r"the time column \(t\) is switched off; give the sample time"):
        load_recording(p, columns={"op": "uEst", "pv": "yEst", "t": None}, op_range=(0, 100))
    with pytest.raises(RecordingError, match=r"both a time column \(t=Ts\) and a sample time \(dt=2\)"):
        load_recording(p, columns={"op": "uEst", "pv": "yEst", "t": "Ts"}, op_range=(0, 100), dt=2.0)
    for bad in (0.0, -1.0, float("nan"), float("inf"), "2", True):
        with pytest.raises(RecordingError, match="dt must be the sample time in seconds"):
            load_recording(p, columns={"op": "uEst", "pv": "yEst"}, op_range=(0, 100), dt=bad)


def test_the_cli_reads_it_with_dt_and_refuses_bad_values(untimed, tmp_path, capsys):
    p, _ = untimed
    base = [str(p), "--columns", "op=uEst,pv=yEst", "--op-range", "0,100", "--effects", "none", "--effort",
            "fast", "--jobs", "1", "--quiet"]
    out = tmp_path / "r.json"
    assert cli.main(base + ["--dt", "2", "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["recording"]["dt"] == 2.0 and d["recording"]["n"] == 300
    for bad in ("0", "-2", "x", "nan", "inf"):
        assert cli.main(base + ["--dt", bad]) == 2
        assert "--dt" in capsys.readouterr().err
    # the one batch engine takes --dt with --out too: the loop is read at 2 s, as without --out
    assert cli.main(base + ["--dt", "2", "--out", str(tmp_path / "fleet")]) == 0
    assert "1 analysed, 0 failed" in capsys.readouterr().out
    assert (tmp_path / "fleet" / "worklist.md").is_file()


def test_the_other_record_of_the_same_file_validates_the_fit(untimed, tmp_path, capsys):
    """``--validate FILE --validate-columns op=uVal,pv=yVal``: the benchmark's test record beside its estimation one."""
    p, _ = untimed
    base = [str(p), "--columns", "op=uEst,pv=yEst", "--op-range", "0,100", "--dt", "2", "--effects", "none",
            "--effort", "fast", "--jobs", "1", "--quiet"]
    out = tmp_path / "v.json"
    assert cli.main(base + ["--validate", str(p), "--validate-columns", "op=uVal,pv=yVal", "--json", str(out)]) == 0
    v = json.loads(out.read_text())["validation"]
    assert v and np.isfinite(v["base_rmse"]) and np.isfinite(v["final_rmse"])
    same = tmp_path / "same.json"
    assert cli.main(base + ["--validate", str(p), "--json", str(same)]) == 0    # the same columns: the same record
    assert json.loads(same.read_text())["validation"]["base_rmse"] != v["base_rmse"]
    assert cli.main(base + ["--validate-columns", "op=uVal,pv=yVal"]) == 2
    assert "give --validate too" in capsys.readouterr().err
