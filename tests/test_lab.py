"""The teaching lab without a browser: the pages build, settings change the traces, the loop page's limit cycle."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest

pytest.importorskip("panel")

from valve_gym import figures  # noqa: E402
from valve_gym.cli import main as cli_main  # noqa: E402
from valve_gym.friction import valve_model  # noqa: E402
from valve_gym.lab import _need  # noqa: E402
from valve_gym.lab.models import CompensatorLab, LoopLab, ValveLab, valve_input  # noqa: E402
from valve_gym.params import ModelParams  # noqa: E402


def _source(layout, name):
    """The Bokeh ColumnDataSource called ``name`` in a Panel layout (the page's plotted data)."""
    import panel as pn
    from bokeh.models import ColumnDataSource

    found = list({m.id: m for pane in layout.select(pn.pane.Bokeh)
                  for m in pane.object.select({"type": ColumnDataSource}) if m.name == name}.values())
    assert len(found) == 1, f"expected one source {name!r}, found {len(found)}"
    return found[0].data


def test_app_builds_three_pages():
    import panel as pn

    from valve_gym.lab import build_app

    app = build_app(sync_url=False)
    tabs = app.select(pn.Tabs)
    assert len(tabs) == 1
    assert [t for t in tabs[0]._names] == ["Valve", "Loop", "Compensator"]


def test_valve_page_z_max_changes_the_stem():
    from valve_gym.lab.app import ValvePage, valve_page

    lab = ValvePage(preset="fig7")
    valve_page(lab)
    before = np.array(_source(lab.plots(), "valve_source")["stem"])
    lab.z_max = 0.02
    after = np.array(_source(lab.plots(), "valve_source")["stem"])
    assert before.shape == after.shape
    assert np.abs(before - after).max() > 0.01     # less friction: the stem follows the ramps much sooner


def test_fig7_preset_is_stick_slip_and_the_healthy_valve_is_not():
    tr = ValveLab(preset="fig7").simulate()
    u, h, g = tr.columns["input"], tr.columns["stem"], tr.columns["healthy_h"]
    ramp = np.abs(np.diff(u)) > 0
    dh, dg = np.abs(np.diff(h)), np.abs(np.diff(g))
    du = np.abs(np.diff(u))
    # while the input ramps, the sticky stem both stands still and jumps (moves far more than the input)
    assert np.sum(ramp & (dh < 1e-9)) > 100
    assert np.sum(ramp & (dh > 5 * du)) >= 3
    assert tr.summary["stem_jumps"] >= 3
    # the jumps are large; the paper's healthy valve follows the ramps with at most small catch-ups
    assert dh[ramp].max() > 0.02
    assert dg[ramp].max() < 0.01


@pytest.mark.parametrize("model", ["choudhury", "kano", "karnopp"])
def test_valve_page_other_friction_models(model):
    lab = ValveLab(preset="fig7")
    lab.param.update(model=model, S=0.05, J=0.03)
    tr = lab.simulate()
    assert np.isfinite(tr.columns["stem"]).all()
    assert tr.summary["stem_jumps"] >= 3, model
    lab.S = 0.0
    lab.J = 0.0
    assert lab.simulate().summary["stem_jumps"] < tr.summary["stem_jumps"]


@pytest.mark.parametrize("kind", ["steps", "ramps", "sine"])
def test_valve_input_length_and_range(kind):
    u = valve_input(kind, 60.0, 0.05)
    assert u.shape == (1200,)
    assert (u >= 0).all() and (u <= 1).all()
    with pytest.raises(ValueError, match="unknown input"):
        valve_input("chirp", 60.0, 0.05)


def test_loop_page_limit_cycle_with_high_friction_only():
    lab = LoopLab()                                    # the paper's tank, high friction (z_max 0.3 s)
    tr = lab.simulate()
    assert tr.summary["lc"] is True
    assert 0.005 < tr.summary["lc_amplitude"] < 0.1     # metres
    assert 30.0 < tr.summary["lc_period"] < 600.0
    ghost_pv = tr.columns["pv_ghost"]
    lab.param.update(z_max=0.0, e_dead=0.0)
    tr0 = lab.simulate()
    assert tr0.summary["lc"] is False
    np.testing.assert_allclose(tr0.columns["pv_ghost"], ghost_pv)    # the ghost is the same frictionless loop
    # the frictionless loop settles at the set point
    assert abs(tr0.columns["pv"][-1] - tr0.columns["sp"][-1]) < 1e-3


def test_loop_page_fig10_low_and_high():
    from valve_gym.lab.app import LoopPage

    lab = LoopPage(fig10=True)
    tr = lab.traces()
    assert tr is not None
    low, high = tr.extra["low"].summary, tr.extra["high"].summary
    assert low["lc"] and high["lc"]
    assert high["lc_amplitude"] > 3 * low["lc_amplitude"]      # more friction, larger cycle
    assert high["lc_period"] < low["lc_period"]                # ... and faster
    lay = lab.plots()
    assert len(_source(lay, "loop_low_source")["pv"]) == len(_source(lay, "loop_high_source")["pv"])


def test_loop_page_flow_loop_and_load():
    lab = LoopLab(process="flow loop", model="choudhury", S=0.0, J=0.0, Kc=0.5, Ti=10.0, sp_step=0.1)
    tr = lab.simulate()
    assert abs(tr.columns["pv"][-1] - 0.6) < 5e-3
    lab.param.update(load=0.05, load_at=1000.0)
    tr2 = lab.simulate()
    k = int(1000 / lab.scan_s)
    assert np.allclose(tr.columns["op"][:k], tr2.columns["op"][:k])
    assert tr2.columns["op"][-1] < tr.columns["op"][-1] - 0.02     # extra inflow: the valve closes


def test_traces_csv_and_png():
    from valve_gym.lab.app import png_bytes

    tr = ValveLab(preset="fig8").simulate()
    text = tr.csv()
    head, first = text.splitlines()[:2]
    assert head.startswith("t_s,input_-,stem_-")
    assert len(text.splitlines()) == tr.t.size + 1
    assert float(first.split(",")[0]) == pytest.approx(tr.t[0])
    assert png_bytes(tr, "valve")[:8] == b"\x89PNG\r\n\x1a\n"
    loop = LoopLab(seconds=600.0, settle=100.0).simulate()
    assert png_bytes(loop, "loop")[:8] == b"\x89PNG\r\n\x1a\n"


def test_compensator_page_scores_and_exercise():
    lab = CompensatorLab(n_loops=2, S=0.06, J=0.03, S_est=0.06)
    tr = lab.simulate()
    s = tr.summary
    assert 0.0 <= s["lc_share"] <= 1.0 and 0.0 <= s["lc_share_pi"] <= 1.0
    assert np.isfinite(s["R"])
    assert s["travel"] > s["travel_pi"]                    # the knocker's pulses move the valve more
    assert tr.columns["pv"].shape == tr.columns["pv_pi"].shape == (3600,)
    lab.exercise = True
    S, J = lab.valve()
    assert (S, J) == lab.valve()                           # the hidden valve is fixed by its seed
    assert 0.01 <= S <= 0.08 and 0.0 < J < S
    lab.exercise_seed = 2
    assert lab.valve() != (S, J)


def test_compensator_page_bad_setting_is_one_line():
    import panel as pn

    from valve_gym.lab.app import CompensatorPage

    lab = CompensatorPage(n_loops=1, controller="knocker")
    lab.param.update(h_k=1.0, tau_k=5.0)      # a pulse longer than the time between pulses: the knocker refuses
    lay = lab.plots()
    assert isinstance(lay, pn.pane.Alert)
    assert "h_k > tau_k" in lab._error and "\n" not in lab._error
    assert lab.traces() is None


def test_figures_valve_response_any_model_and_loop_load():
    p = valve_model("choudhury", S=0.04, J=0.02, base=ModelParams())
    u = figures.multi_ramp([0.6, 0.4], [0.01, 0.01], 0.05)
    r = figures.valve_response(p, u, 0.05)
    assert r.stuck is not None and set(np.unique(r.stuck)) <= {0.0, 1.0} and r.stuck.max() == 1.0
    assert figures.valve_response(figures.HEALTHY, u, 0.05).stuck is None
    base = figures.closed_loop_pi(ModelParams(), 1.0, 1.0, 30.0, seconds=300.0)
    loaded = figures.closed_loop_pi(ModelParams(), 1.0, 1.0, 30.0, seconds=300.0, load=np.full(300, 1e-3))
    assert loaded.op[-1, 0] < base.op[-1, 0]
    with pytest.raises(ValueError, match="load must be"):
        figures.closed_loop_pi(ModelParams(), 1.0, 1.0, 30.0, seconds=300.0, load=np.zeros(3))


def test_cli_help_and_bad_port(capsys):
    with pytest.raises(SystemExit) as ex:
        cli_main(["lab", "--help"])
    assert ex.value.code == 0
    assert "--no-browser" in capsys.readouterr().out
    with pytest.raises(SystemExit) as ex:
        cli_main(["lab", "--port", "70000"])
    assert ex.value.code == 2
    assert "--port must be between 0 and 65535" in capsys.readouterr().err


def test_missing_panel_is_one_line(monkeypatch, capsys):
    real = importlib.util.find_spec
    monkeypatch.setattr(_need.importlib.util, "find_spec", lambda name, *a: None if name == "panel" else real(name, *a))
    with pytest.raises(ImportError, match=r'pip install "valve_gym\[lab\]"'):
        _need.need_panel()
    assert cli_main(["lab", "--no-browser"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['valve-gym lab: the teaching lab needs Panel and Bokeh: pip install "valve_gym[lab]"']


def test_valve_preset_applies_and_a_moved_setting_leaves_it():
    lab = ValveLab(preset="fig6")
    assert (lab.input, lab.seconds, lab.z_max) == ("sine", 200.0, figures.STICKY.z_max)
    lab.z_max = 0.05
    assert lab.preset == "custom" and lab.z_max == 0.05
    lab.preset = "fig8"
    assert (lab.input, lab.z_max) == ("steps", figures.STICKY.z_max)
