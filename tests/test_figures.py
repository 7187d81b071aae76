"""Tests of valve_gym.figures: the command's files and the numbers behind each figure."""

from __future__ import annotations

import csv
import doctest
import os
import subprocess
import sys

import numpy as np
import pytest

from valve_gym import figures as F
from valve_gym.control import PIParams, pi_init, pi_step
from valve_gym.core import initial_state, step
from valve_gym.params import ModelParams, ValveParams

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
PNGS = ["valve_io.png", "valve_steps.png", "stick_slip_ramps.png", "limit_cycles.png"]


def test_module_doctest():
    res = doctest.testmod(F, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert res.failed == 0 and res.attempted > 0


# --------------------------------------------------------------------------
# the command
# --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    out = tmp_path_factory.mktemp("figures") / "sub"  # created by the command
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = F.main(["--out", str(out), "--dpi", "60"])
    return out, rc, buf.getvalue()


def test_command_writes_every_file(written):
    out, rc, stdout = written
    assert rc == 0
    names = sorted(os.listdir(out))
    assert names == sorted(PNGS + ["limit_cycles.md", "limit_cycles.csv"])  # no temp files left
    for name in names:
        assert os.path.join(str(out), name) in stdout.splitlines()


@pytest.mark.parametrize("name", PNGS)
def test_pngs_are_valid(written, name):
    import matplotlib.image as mpimg

    out, _, _ = written
    path = out / name
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    img = mpimg.imread(str(path))
    assert img.ndim == 3 and img.shape[0] > 200 and img.shape[1] > 400
    # not a blank canvas: a fair share of non-white pixels
    assert (img[..., :3] < 0.9).any(axis=2).mean() > 0.01


def test_dpi_sets_the_size(written):
    import matplotlib.image as mpimg

    out, _, _ = written
    w60 = mpimg.imread(str(out / "valve_io.png")).shape[1]
    fig = F.plot_valve_io(F.valve_io_data(seconds=20.0))
    path = out.parent / "io120.png"
    F._save_figure(fig, str(path), 120)
    assert mpimg.imread(str(path)).shape[1] == pytest.approx(2 * w60, abs=2)


def test_table_files_and_printout(written):
    out, _, stdout = written
    md = (out / "limit_cycles.md").read_text()
    lines = md.strip().splitlines()
    assert lines[0].startswith("| friction | z_max [s] | e_dead [-] | limit cycle | amplitude [m]")
    assert len(lines) == 2 + len(F.FRICTION_LEVELS)
    assert md.strip() in stdout  # the table is printed too
    with open(out / "limit_cycles.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["friction"] for r in rows] == [lv[0] for lv in F.FRICTION_LEVELS]
    by = {r["friction"]: r for r in rows}
    assert by["none"]["limit_cycle"] == "0" and float(by["none"]["period_s"]) == np.inf
    assert by["high"]["limit_cycle"] == "1" and float(by["high"]["amplitude_m"]) > 0.005


def test_progress_lines(written):
    _, _, stdout = written
    assert [ln for ln in stdout.splitlines() if ln.startswith("[")][-1].startswith("[4/4]")


@pytest.mark.parametrize("argv", [[], ["--out"], ["--out", "x", "--dpi", "5"],
                                  ["--out", "x", "--dpi", "many"]])
def test_bad_arguments_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        F.main(argv)
    assert exc.value.code == 2
    assert "usage: valve-gym figures" in capsys.readouterr().err


def test_cli_dispatches_to_figures(tmp_path, capsys):
    from valve_gym import cli

    with pytest.raises(SystemExit) as exc:
        cli.main(["figures", "--help"])
    assert exc.value.code == 0
    assert "--dpi" in capsys.readouterr().out


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    def boom(f):
        f.write(b"half a file")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        F._write_atomic(str(tmp_path / "x.png"), boom)
    assert os.listdir(tmp_path) == []
    # and a successful write replaces an existing file in one step
    (tmp_path / "x.png").write_bytes(b"old")
    F._write_atomic(str(tmp_path / "x.png"), lambda f: f.write(b"new"))
    assert (tmp_path / "x.png").read_bytes() == b"new"
    assert os.listdir(tmp_path) == ["x.png"]


def test_matplotlib_is_imported_lazily():
    code = "import sys, valve_gym.figures; print('matplotlib' in sys.modules)"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "False"


# --------------------------------------------------------------------------
# open-loop signatures
# --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ramps():
    return F.stick_slip_data()


def _steady_motion(u, window):
    """Samples whose input has moved monotonically (no hold, no reversal) for ``window`` samples."""
    sg = np.sign(np.r_[0.0, np.diff(u)])
    ok = np.zeros(u.size, bool)
    for k in range(window, u.size):
        ok[k] = sg[k] != 0 and np.all(sg[k - window + 1:k + 1] == sg[k])
    return ok


def _stuck_runs(r, min_len, tol=1e-3):
    """(start, stop) sample ranges of at least ``min_len`` samples in which the stem
    stays within ``tol`` (fraction of the stroke) of where it was at ``start``."""
    runs, k, n = [], 0, r.h.size
    while k < n - 1:
        j = k + 1
        while j < n and abs(r.h[j] - r.h[k]) <= tol:
            j += 1
        if j - 1 - k >= min_len:
            runs.append((k, j - 1))
            k = j - 1
        else:
            k += 1
    return runs


def test_sticky_valve_sticks_then_jumps(ramps):
    _, sticky = ramps
    dt_s = sticky.t[1] - sticky.t[0]
    ed = F.STICKY.e_dead
    runs = [(a, b) for a, b in _stuck_runs(sticky, int(2.0 / dt_s))
            if abs(sticky.u[b] - sticky.u[a]) > 2 * ed]
    # stuck for >= 2 s while the input moves by more than the dead band, at every reversal
    assert len(runs) >= 4
    w = int(0.5 / dt_s)
    max_input_step = np.max(np.abs(sticky.u[w:] - sticky.u[:-w]))
    for a, b in runs:
        if b + w < sticky.h.size:
            jump = abs(sticky.h[b + w] - sticky.h[b])
            # then it jumps: in 0.5 s it moves more than twice what the input does
            assert jump > 2 * max_input_step, (sticky.t[b], jump)
    # while stuck after a reversal, z crosses its band from one edge to the other
    # (the first run is the start from rest, z = 0)
    assert sticky.z[runs[0][0]] == 0.0
    for a, b in runs[1:]:
        assert abs(sticky.z[a]) >= sticky.z_max
        after = sticky.z[min(b + w, sticky.z.size - 1)]
        assert sticky.z[a] * after < 0 and abs(after) >= sticky.z_max


def test_healthy_valve_follows_within_dead_band(ramps):
    healthy, sticky = ramps
    dt_s = healthy.t[1] - healthy.t[0]
    s_max = 0.02  # 1/s, fastest ramp of the experiment
    v = F.HEALTHY
    ok = _steady_motion(healthy.u, int(5.0 / dt_s))
    assert ok.sum() > 1000
    lag = np.abs(healthy.u - healthy.h)[ok]
    # in steady motion the lag is e_dead + s*tau (oracle O1), plus 1e-3 of margin
    assert lag.max() <= v.e_dead + s_max * v.tau + 1e-3
    assert lag.min() >= v.e_dead
    # anywhere (reversals included) within the reversal travel of oracle O2
    o2 = 2 * v.e_dead + s_max * v.tau * np.log(2) + 2 * np.sqrt(s_max * v.z_max)
    assert np.abs(healthy.u - healthy.h).max() <= o2
    assert np.abs(sticky.u - sticky.h).max() > 3 * o2
    # it sticks only briefly at reversals: never longer than the O2 input travel
    for a, b in _stuck_runs(healthy, int(1.0 / dt_s)):
        assert abs(healthy.u[b] - healthy.u[a]) <= o2


def test_valve_io_loop_width():
    """At mid-stroke the loop is 2 (e_dead + s tau) wide: the two branches lag both ways."""
    period, amp = 100.0, 0.3
    s = 2 * np.pi * amp / period  # input speed at mid-stroke, 1/s
    for r, v in zip(F.valve_io_data(seconds=200.0, period=period, amplitude=amp),
                    (F.HEALTHY, F.STICKY)):
        k = r.t > period  # second cycle
        u, h = r.u[k], r.h[k]
        d = np.diff(u)
        mid = np.abs(u[1:] - 0.5) < 0.003
        width = h[1:][mid & (d < 0)].mean() - h[1:][mid & (d > 0)].mean()
        assert width == pytest.approx(2 * (v.e_dead + s * v.tau), abs=1e-3)
        assert r.h.min() >= 0.2 - 1e-9 and r.h.max() <= 0.8 + 1e-9


def test_valve_steps():
    healthy, sticky = F.valve_steps_data(step=0.05, n_steps=4, hold=15.0)
    dt_s = healthy.t[1] - healthy.t[0]
    ends = (np.arange(1, 10) * 15.0 / dt_s).astype(int) - 1  # last sample of each step
    levels = healthy.u[ends]
    direction = np.sign(np.r_[0.0, np.diff(levels)])
    # the healthy valve settles at input - e_dead*direction on every step
    np.testing.assert_allclose(healthy.h[ends[1:]],
                               levels[1:] - F.HEALTHY.e_dead * direction[1:], atol=1e-6)
    # the sticky valve: the first step down (0.05) gives a dead time
    # 2 z_max / (0.05 - 2 e_dead) = 40 s > 15 s: it does not move during it
    first_down = slice(ends[4] + 1, ends[5] + 1)
    assert np.ptp(sticky.h[first_down]) < 1e-3
    # the next one releases it; it then ends one dead band above the input
    assert sticky.h[ends[6]] == pytest.approx(levels[6] + F.STICKY.e_dead, abs=1e-6)


def test_valve_response_errors():
    with pytest.raises(ValueError, match="whole number of Euler steps"):
        F.valve_response(F.HEALTHY, np.full(10, 0.5), sample_time=0.0105)
    with pytest.raises(ValueError, match="finite"):
        F.valve_response(F.HEALTHY, np.array([0.5, np.nan]), sample_time=0.01)


# --------------------------------------------------------------------------
# closed loop
# --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cases():
    return {c.name: c for c in F.limit_cycle_data()}


def test_limit_cycle_with_friction_and_none_without(cases):
    assert not cases["none"].present
    assert cases["none"].amplitude == 0.0 and cases["none"].period == np.inf
    for name in ("low", "medium", "high"):
        c = cases[name]
        assert c.present and c.n_cycles >= 5, name
    # the frictionless loop settles at the set point
    run = cases["none"].run
    assert np.max(np.abs(run.pv[-500:, 0] - 1.2)) < 1e-4


def test_more_friction_bigger_and_faster_limit_cycle(cases):
    """What the simulator shows for this loop (and what the paper states)."""
    amp = [cases[n].amplitude for n in ("low", "medium", "high")]
    per = [cases[n].period for n in ("low", "medium", "high")]
    assert amp[0] < amp[1] < amp[2]
    assert per[0] > per[1] > per[2]
    # the high-friction PV swings several cm
    assert amp[2] > 0.01


def test_sticky_loop_stem_moves_in_jumps(cases):
    run = cases["high"].run
    stem, op = run.stem[-1000:, 0], run.op[-1000:, 0]
    moves = np.abs(np.diff(stem))
    # the stem is still in most control samples, while OP ramps in almost all of them
    assert np.mean(moves < 1e-6) > 0.8
    assert np.mean(np.abs(np.diff(op)) > 1e-5) > 0.9
    # and its moves come in jumps far larger than one OP increment
    assert moves.max() > 10 * np.abs(np.diff(op)).max()


def test_closed_loop_matches_step_by_step_reference():
    """closed_loop_pi = the PI law and core.step called by hand, sample by sample."""
    p = ModelParams(valve=ValveParams(z_max=0.05, e_dead=0.005))
    Kc, Ti, Ts, T = 1.0, 30.0, 1.0, 120
    r = F.closed_loop_pi(p, 1.1, Kc, Ti, Ts, T * Ts)
    st = initial_state(p, 1)
    pi = PIParams(Kc=Kc, Ti=Ti, Ts=Ts)
    ctl = pi_init(st.h, 1.1 - st.y)
    n_sub = int(round(Ts / p.dt))
    for k in range(T):
        assert r.pv[k, 0] == st.y[0]
        assert r.stem[k, 0] == np.clip(st.h[0], 0, 1)
        ctl, u = pi_step(ctl, 1.1 - st.y, pi)
        assert r.op[k, 0] == u[0]
        st, _ = step(st, u, p, n_sub=n_sub)
    np.testing.assert_array_equal(r.t, np.arange(T) * Ts)
    assert np.all(r.sp == 1.1)


def test_closed_loop_batch_and_noise():
    v = ValveParams(z_max=np.array([0.0, 0.3]), e_dead=np.array([0.0, 0.01]))
    p = ModelParams(valve=v)
    a = F.closed_loop_pi(p, 1.1, 1.0, 30.0, 1.0, 200.0, noise_std=0.002, seed=3)
    b = F.closed_loop_pi(p, 1.1, 1.0, 30.0, 1.0, 200.0, noise_std=0.002, seed=3)
    c = F.closed_loop_pi(p, 1.1, 1.0, 30.0, 1.0, 200.0, noise_std=0.002, seed=4)
    for name in a._fields:
        assert getattr(a, name).shape == ((200,) if name == "t" else (200, 2))
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.pv, c.pv)
    # the noise is on the measurement only
    resid = a.pv - a.level
    assert 0.0015 < resid.std() < 0.0025
    # set-point profile (T,) and per-loop gains (n,)
    sp = np.r_[np.full(100, 1.0), np.full(100, 1.3)]
    d = F.closed_loop_pi(p, sp, np.array([1.0, 2.0]), 30.0, 1.0, 200.0)
    np.testing.assert_array_equal(d.sp[:, 1], sp)


def test_closed_loop_errors():
    p = ModelParams()
    with pytest.raises(ValueError, match="whole number of Euler steps"):
        F.closed_loop_pi(p, 1.0, 1.0, 30.0, control_period=0.03)
    with pytest.raises(ValueError, match="noise_std"):
        F.closed_loop_pi(p, 1.0, 1.0, 30.0, seconds=10.0, noise_std=-1.0)
    with pytest.raises(ValueError, match="sp must be"):
        F.closed_loop_pi(p, np.ones(7), 1.0, 30.0, seconds=10.0)
    with pytest.raises(ValueError, match="shorter than one control period"):
        F.closed_loop_pi(p, 1.0, 1.0, 30.0, seconds=0.1)
    with pytest.raises(ValueError, match="Ti must be > 0"):
        F.closed_loop_pi(p, 1.0, 1.0, 0.0, seconds=10.0)


def test_limit_cycle_table_formats(cases):
    md = F.limit_cycle_markdown(list(cases.values()))
    assert "| none | 0 | 0 | no | - | - | 0 |" in md
    rows = F.limit_cycle_rows(list(cases.values()))
    assert [r[0] for r in rows] == ["none", "low", "medium", "high"]
