"""The lab's pages: Panel layouts of the experiments of :mod:`valve_gym.lab.models`, Bokeh plots.

:func:`build_app` returns the whole lab (three tabs: valve, loop,
compensator); :func:`valve_page`, :func:`loop_page` and
:func:`compensator_page` one page each. They build without a browser (a test
can call them and read the plots' data sources). When served, each page's
settings and the open tab are kept in the URL's query string
(``pn.state.location.sync``), so a link reproduces the view.

Every page has a CSV download of its traces and a PNG download of its
figure (drawn by matplotlib from the same traces, no browser needed).
"""
from __future__ import annotations

import io
from collections.abc import Callable
from typing import Any

from ._need import need_panel

need_panel()

import numpy as np  # noqa: E402
import panel as pn  # noqa: E402
import param  # noqa: E402
from bokeh.models import BoxAnnotation, ColumnDataSource, Range1d  # noqa: E402
from bokeh.plotting import figure  # noqa: E402

from .models import CompensatorLab, LoopLab, Traces, ValveLab, fmt_lc  # noqa: E402

__all__ = ["build_app", "valve_page", "loop_page", "compensator_page", "ValvePage", "LoopPage", "CompensatorPage",
           "png_bytes"]

_C = {"input": "#444444", "stem": "#d62728", "ghost": "#9e9e9e", "sp": "#444444", "pv": "#1f77b4",
      "op": "#ff7f0e", "pi": "#9e9e9e"}
_W = 640


def _fig(title: str, x: str, y: str, height: int = 260, x_range=None, width: int = _W, **kw):
    f = figure(title=title, height=height, width=width, x_axis_label=x, y_axis_label=y,
               tools="pan,wheel_zoom,box_zoom,reset", toolbar_location="right", **kw)
    if x_range is not None:
        f.x_range = x_range
    return f


def _legend(f, loc="top_left"):
    f.legend.location = loc
    f.legend.click_policy = "hide"
    f.legend.label_text_font_size = "9pt"
    f.legend.background_fill_alpha = 0.6


class _Cached(param.Parameterized):
    """Mixin: one simulation per settings, shared by the plots, the summary and the downloads."""

    _key = None
    _traces: Traces | None = None
    _error: str = ""

    def traces(self) -> Traces | None:
        """The traces of the current settings (simulated once; ``None`` with an error message in ``_error``)."""
        vals = self.param.values()
        vals.pop("name", None)
        key = tuple(sorted((k, repr(v)) for k, v in vals.items()))
        if key != self._key:
            try:
                self._traces, self._error = self.simulate(), ""
            except ValueError as exc:            # a setting the model refuses: say which
                self._traces, self._error = None, str(exc).splitlines()[0]
            self._key = key
        return self._traces

    def simulate(self) -> Traces:  # pragma: no cover - provided by the model class
        raise NotImplementedError

    def _error_pane(self):
        return pn.pane.Alert(f"Cannot simulate these settings: {self._error}", alert_type="danger")

    def downloads(self, stem: str):
        """CSV and PNG download buttons of the current traces."""
        def csv():
            tr = self.traces()
            return io.StringIO(tr.csv() if tr is not None else "")

        def png():
            tr = self.traces()
            return io.BytesIO(png_bytes(tr, stem) if tr is not None else b"")

        return pn.Row(pn.widgets.FileDownload(callback=csv, filename=f"{stem}_traces.csv", label="traces (CSV)",
                                              css_classes=[f"vg-{stem}-csv"]),
                      pn.widgets.FileDownload(callback=png, filename=f"{stem}.png", label="figure (PNG)",
                                              css_classes=[f"vg-{stem}-png"]))


# --------------------------------------------------------------------------- the valve
_VALVE_TEXT = """
### The valve (Riihilahti's model, as in the paper)

Input `i` (controller output) and stem position `h`, both fractions of the stroke (0..1):

```
e     = i - h,   e <- e - e_dead sign(e)  if |e| > e_dead, else 0      (dead band)
dz/dt = max(e, 0) if z < -z_max;  min(e, 0) if z > z_max;  e otherwise  (friction band)
dh/dt = sign(e) min(|e| / tau, v_max)   if |z| > z_max, else 0          (stem moves)
```

* **tau** [s]: time constant of the stem's first-order motion.
* **v_max** [stroke/s]: stem speed limit.
* **e_dead** [fraction of stroke]: half the dead band (backlash).
* **z_max** [s]: half width of the integral friction band: after a reversal the stem waits
  until `z` has crossed `2 z_max`, then slips.

The other models are sized by the stick band **S** and the slip jump **J** (fractions of stroke):
after a reversal the stem stays until the input has moved `S`, then jumps `J` (Choudhury, Kano);
Karnopp's force balance gives the same with mass and viscous friction. `tau` is their positioner lag.

Grey: the paper's healthy valve (tau = 0.1 s, e_dead = 0.005, z_max = 0.005 s) on the same input.
Presets: **fig6** slow sine (input vs stem), **fig7** ramps (stick-slip), **fig8** staircase.
"""


class ValvePage(ValveLab, _Cached):
    """The valve page: :class:`~valve_gym.lab.models.ValveLab` with its plots."""

    @param.depends("model")
    def friction_controls(self):
        """The sliders of the chosen friction model."""
        names = ["e_dead", "z_max"] if self.model == "riihilahti" else ["S", "J"]
        return pn.Param(self, parameters=names, show_name=False, widgets=_slider_classes(names, "v"))

    @param.depends(*ValveLab.param, watch=False)
    def plots(self):
        """Input vs stem, the time responses and the friction state (Bokeh)."""
        tr = self.traces()
        if tr is None:
            return self._error_pane()
        c = tr.columns
        data: dict[str, Any] = dict(t=tr.t, input=c["input"], stem=c["stem"], healthy=c["healthy_h"],
                                    friction=c["friction"])
        src = ColumnDataSource(data=data, name="valve_source")
        io_ = _fig("Input vs stem position", "input i [fraction of stroke]", "stem h [fraction of stroke]",
                   height=330, width=380, match_aspect=True)
        lo, hi = float(c["input"].min()), float(c["input"].max())
        io_.line([lo, hi], [lo, hi], color="#bbbbbb", line_dash="dotted", legend_label="ideal h = i")
        io_.line("input", "healthy", source=src, color=_C["ghost"], line_width=1.5, legend_label="healthy valve")
        io_.line("input", "stem", source=src, color=_C["stem"], line_width=2, legend_label="this valve")
        _legend(io_)
        tf = _fig("Time response", "time [s]", "[fraction of stroke]", height=250, width=580)
        tf.line("t", "input", source=src, color=_C["input"], line_dash="dashed", legend_label="input i")
        tf.line("t", "healthy", source=src, color=_C["ghost"], line_width=1.5, legend_label="healthy stem")
        tf.line("t", "stem", source=src, color=_C["stem"], line_width=2, legend_label="stem h")
        _legend(tf)
        unit = tr.summary["friction_unit"]
        ylab = {"z/z_max": "z / z_max [-]", "stuck": "stuck (1) / moving (0)"}.get(unit, "stem velocity [stroke/s]")
        ff = _fig("Friction state", "time [s]", ylab, height=180, x_range=tf.x_range, width=580)
        if unit == "z/z_max":
            ff.add_layout(BoxAnnotation(bottom=-1, top=1, fill_color="#dddddd", fill_alpha=0.6))
        ff.line("t", "friction", source=src, color=_C["stem"], line_width=1.5)
        jumps = tr.summary["stem_jumps"]
        note = pn.pane.Markdown(
            f"**{jumps} stem jump(s)** (stick-slip: the stem stands still, then moves at once), "
            f"stem travel {tr.summary['stem_travel']:.3f} strokes. Grey band: `|z| <= z_max`, the stem is stuck.",
            css_classes=["vg-valve-summary"], width=380)
        return pn.Row(pn.Column(io_, note), pn.Column(tf, ff))


def _layout(controls, plots, text: str, page: str):
    """Controls on the left; the plots, and under them the equations and how to read the plots."""
    card = pn.Card(pn.pane.Markdown(text, width=960), title="The model, its equations and how to read the plots",
                   collapsed=False, width=990)
    view = pn.param.ParamMethod(plots, lazy=True, loading_indicator=True)    # simulated when first shown
    return pn.Row(controls, pn.Column(view, card), css_classes=[f"vg-page-{page}"])


def _slider_classes(names, prefix: str) -> dict:
    return {n: {"css_classes": [f"vg-{prefix}-{n}"]} for n in names}


def _friction_page(lab, first: list, heading: str, rest: list, prefix: str, name: str, text: str):
    """A page whose controls are ``first``, the friction model's own controls, ``heading`` and ``rest``."""
    controls = pn.Column(
        pn.Param(lab, parameters=first, show_name=False, widgets=_slider_classes(first, prefix)),
        lab.friction_controls,
        pn.pane.Markdown(f"**{heading}**"),
        pn.Param(lab, parameters=rest, show_name=False, widgets=_slider_classes(rest, prefix)),
        lab.downloads(name), width=320)
    return _layout(controls, lab.plots, text, name)


def valve_page(lab: ValvePage | None = None):
    """The valve page (a Panel layout); ``lab`` its settings (default the fig-7 preset)."""
    lab = ValvePage(preset="fig7") if lab is None else lab
    common = ["preset", "model", "tau", "v_max"]
    sig = ["input", "seconds", "step", "hold", "ramp_speed", "amplitude", "period"]
    return _friction_page(lab, common, "Input signal", sig, "v", "valve", _VALVE_TEXT)


# --------------------------------------------------------------------------- the loop
_LOOP_TEXT = """
### The loop

The paper's tank: inflow through the valve, outflow through an orifice,

```
A dL/dt = q_max f(h) + d - k sqrt(L)      (level L [m]; load d = load step x q_max, q_max = 0.01 m^3/s)
```

under the PI law (scan 1 s): `u = Kc (e + (1/Ti) sum e Ts)`, `e = SP - PV`. The flow loop is a
first-order process `T dy/dt = f(h) + d - y` (T = 10 s), PV a fraction of the maximum flow.

With friction the loop cycles (figures 9-10): the stem sticks while the PI's integral winds up,
then slips past the target; the stem moves as a square wave, the OP and the level as triangles
(saw teeth). More friction, a larger and faster cycle. The **limit cycle** is read on `SP - PV` after the
transient by the benchmark's detector
(`valve_gym.oscillation.detect_oscillation`: a regular, undamped autocorrelation; amplitude is half the
peak-to-peak). Grey: the same loop with a frictionless valve.

**fig10**: the paper's low- and high-friction valves side by side (z_max = 0.005 / 0.3 s,
e_dead = 0.002 / 0.01).
"""


class LoopPage(LoopLab, _Cached):
    """The loop page: :class:`~valve_gym.lab.models.LoopLab` with its plots."""

    @param.depends("model")
    def friction_controls(self):
        """The sliders of the chosen friction model."""
        names = ["e_dead", "z_max"] if self.model == "riihilahti" else ["S", "J"]
        return pn.Param(self, parameters=names, show_name=False, widgets=_slider_classes(names, "l"))

    def _loop_figs(self, tr: Traces, title: str, ghost: bool, width: int = _W, name: str = "loop_source"):
        c = tr.columns
        unit = "m" if self.process == "level tank" or self.fig10 else "fraction"
        data: dict[str, Any] = dict(t=tr.t, sp=c["sp"], pv=c["pv"], op=c["op"], stem=c["stem"])
        if ghost and "pv_ghost" in c:
            data.update(pv_ghost=c["pv_ghost"], op_ghost=c["op_ghost"])
        src = ColumnDataSource(data=data, name=name)
        k0 = tr.t >= tr.t[-1] - 800.0
        xr = Range1d(start=float(tr.t[k0][0]), end=float(tr.t[-1]))
        top = _fig(title, "time [s]", f"level / PV [{unit}]", height=260, width=width, x_range=xr)
        top.line("t", "sp", source=src, color=_C["sp"], line_dash="dashed", legend_label="SP")
        if "pv_ghost" in data:
            top.line("t", "pv_ghost", source=src, color=_C["ghost"], line_width=1.5, legend_label="PV, frictionless")
        top.line("t", "pv", source=src, color=_C["pv"], line_width=1.8, legend_label="PV")
        _legend(top, "bottom_right")
        bot = _fig("", "time [s]", "OP, stem [fraction of stroke]", height=220, x_range=xr, width=width)
        if "op_ghost" in data:
            bot.line("t", "op_ghost", source=src, color=_C["ghost"], line_width=1.5, legend_label="OP, frictionless")
        bot.line("t", "op", source=src, color=_C["op"], line_width=1.5, legend_label="OP")
        bot.line("t", "stem", source=src, color=_C["stem"], line_width=1.5, legend_label="stem")
        _legend(bot, "bottom_right")
        for f, keys in ((top, ("sp", "pv")), (bot, ("op", "stem"))):
            lo = min(float(np.min(data[k][k0])) for k in keys)
            hi = max(float(np.max(data[k][k0])) for k in keys)
            pad = max(0.15 * (hi - lo), 0.005)
            f.y_range = Range1d(start=lo - pad, end=hi + pad)
        return pn.Column(top, bot)

    @param.depends(*LoopLab.param, watch=False)
    def plots(self):
        """SP/PV and OP/stem against time, with the frictionless ghost (last 800 s shown; zoom out for all)."""
        tr = self.traces()
        if tr is None:
            return self._error_pane()
        unit = "m" if self.process == "level tank" or self.fig10 else "-"
        if self.fig10:
            cols = []
            for key in ("low", "high"):
                sub = tr.extra[key]
                s = sub.summary
                head = f"{key} friction: z_max = {s['z_max']:g} s, e_dead = {s['e_dead']:g}"
                md = pn.pane.Markdown(f"**{head}** -- {fmt_lc(s)}", css_classes=[f"vg-lc-{key}"])
                cols.append(pn.Column(md, self._loop_figs(sub, head, False, width=460, name=f"loop_{key}_source")))
            return pn.Row(*cols)
        lc = pn.pane.Markdown(f"**{fmt_lc(tr.summary, unit)}** (benchmark detector on SP - PV after "
                              f"{self.settle:g} s)", css_classes=["vg-lc"])
        return pn.Column(lc, self._loop_figs(tr, "Set point, level and the frictionless ghost", True))


def loop_page(lab: LoopPage | None = None):
    """The loop page (a Panel layout); ``lab`` its settings (default: the paper's tank, high friction)."""
    lab = LoopPage() if lab is None else lab
    first = ["fig10", "process", "model"]
    rest = ["Kc", "Ti", "sp_step", "sp_at", "load", "load_at", "seconds", "settle"]
    return _friction_page(lab, first, "PI and the run", rest, "l", "loop", _LOOP_TEXT)


# --------------------------------------------------------------------------- the compensators
_COMP_TEXT = """
### Friction compensators

Each is a PI (the benchmark's SIMC tuning) plus a rule, given a stiction estimate **S_est**:

* **knocker** (Hägglund): pulses of amplitude `a` (default S/2) and width `tau_k` every `h_k` s,
  in the direction the PI's integral part moved: `u = u_PI + a sign(I(t_p) - I(t_p - h_k))`.
* **constant reinforcement**: `u = u_PI + a sign(du_PI/dt)` (default `a = (S - J)/2`).
* **two-move**: moves the valve in two steps to land past the stick band, then holds.
* **integral freeze**: no integration while `|e| < band`.
* **learned**: the shipped learned compensator.

The loops are the benchmark's regulation task (OU load, 2 mm noise, 1 h at 1 s scan), all with the
valve set here. Scores, as in the benchmark (median over the loops):

```
R = (IAE_PI - IAE_c) / max(IAE_PI - IAE_0, 0.1 IAE_0)
```

1 = all of stiction's cost removed, 0 = no better than the PI, < 0 worse (`IAE_0`: the PI on a
frictionless valve). LC share: loops with a limit cycle; travel: stem strokes per hour.

**Exercise**: the valve's S is hidden; tune the compensator (S_est, a, h_k), read R, then reveal S.
"""


class CompensatorPage(CompensatorLab, _Cached):
    """The compensator page: :class:`~valve_gym.lab.models.CompensatorLab` with its plots."""

    @param.depends("controller", "exercise")
    def setting_controls(self):
        """The chosen compensator's own settings (empty: its default rule)."""
        if self.controller == "learned":           # the trained block: it estimates the stick band itself
            return pn.pane.Markdown("The learned compensator runs with its trained settings and estimates the "
                                    "stick band online from SP, PV and its own output.", width=300)
        names = ["S_est", *self.own_settings()]
        widgets = _slider_classes(names, "c")
        for n in self.own_settings():
            widgets[n] = {"type": pn.widgets.FloatInput, "css_classes": [f"vg-c-{n}"], "placeholder": "rule"}
        return pn.Param(self, parameters=names, show_name=False, widgets=widgets)

    @param.depends("exercise")
    def valve_controls(self):
        """The valve's sliders, or the exercise's controls."""
        if self.exercise:
            return pn.Param(self, parameters=["exercise_seed", "reveal"], show_name=False,
                            widgets=_slider_classes(["exercise_seed", "reveal"], "c"))
        return pn.Param(self, parameters=["model", "S", "J"], show_name=False,
                        widgets=_slider_classes(["model", "S", "J"], "c"))

    @param.depends(*CompensatorLab.param, watch=False)
    def plots(self):
        """Scores table and loop 0's traces, PI (grey) against the compensator."""
        tr = self.traces()
        if tr is None:
            return self._error_pane()
        s = tr.summary
        hidden = self.exercise and not self.reveal
        valve = ("S = ?, J = ? (hidden: tune, then reveal)" if hidden else
                 f"S = {100 * s['S']:.2f} %, J = {100 * s['J']:.2f} %")
        table = (f"**Valve**: {self.model}, {valve}; {self.n_loops} loops\n\n"
                 "| | PI (SIMC) | " + self.controller + " |\n|---|---:|---:|\n"
                 f"| LC share | {s['lc_share_pi']:.2f} | {s['lc_share']:.2f} |\n"
                 f"| LC amplitude [mm] | {1000 * s['lc_amplitude_pi']:.1f} | {1000 * s['lc_amplitude']:.1f} |\n"
                 f"| IAE [m s/h] | {s['iae_pi']:.2f} | {s['iae']:.2f} |\n"
                 f"| R | 0 | **{s['R']:.2f}** |\n"
                 f"| travel [strokes/h] | {s['travel_pi']:.2f} | {s['travel']:.2f} |\n\n"
                 f"Settings: `{s['settings'] if len(s['settings']) < 200 else s['settings'][:200] + '...'}`")
        c = tr.columns
        data: dict[str, Any] = dict(t=tr.t, sp=c["sp"], pv=c["pv"], op=c["op"], stem=c["stem"], pv_pi=c["pv_pi"],
                                    op_pi=c["op_pi"], stem_pi=c["stem_pi"])
        src = ColumnDataSource(data=data, name="comp_source")
        xr = Range1d(start=0.0, end=min(900.0, float(tr.t[-1])))
        top = _fig("Loop 1: level", "time [s]", "level [m]", height=240, x_range=xr)
        top.line("t", "sp", source=src, color=_C["sp"], line_dash="dashed", legend_label="SP")
        top.line("t", "pv_pi", source=src, color=_C["pi"], legend_label="PV, PI")
        top.line("t", "pv", source=src, color=_C["pv"], line_width=1.5, legend_label=f"PV, {self.controller}")
        _legend(top, "bottom_right")
        bot = _fig("", "time [s]", "[fraction of stroke]", height=220, x_range=xr)
        bot.line("t", "stem_pi", source=src, color=_C["pi"], legend_label="stem, PI")
        bot.line("t", "op", source=src, color=_C["op"], legend_label=f"OP, {self.controller}")
        bot.line("t", "stem", source=src, color=_C["stem"], line_width=1.5, legend_label=f"stem, {self.controller}")
        _legend(bot, "bottom_right")
        return pn.Column(pn.pane.Markdown(table, css_classes=["vg-comp-scores"]), top, bot)


def compensator_page(lab: CompensatorPage | None = None):
    """The compensator page (a Panel layout); ``lab`` its settings (default knocker on Choudhury S = 4 %)."""
    lab = CompensatorPage() if lab is None else lab
    controls = pn.Column(
        pn.Param(lab, parameters=["controller", "exercise"], show_name=False,
                 widgets=_slider_classes(["controller", "exercise"], "c")),
        lab.valve_controls, lab.setting_controls,
        pn.Param(lab, parameters=["n_loops", "seed"], show_name=False,
                 widgets=_slider_classes(["n_loops", "seed"], "c")),
        lab.downloads("compensator"), width=320)
    return _layout(controls, lab.plots, _COMP_TEXT, "compensator")


# --------------------------------------------------------------------------- the app
_PAGES: tuple[tuple[str, type, Callable, str], ...] = (
    ("Valve", ValvePage, valve_page, "v"),
    ("Loop", LoopPage, loop_page, "l"),
    ("Compensator", CompensatorPage, compensator_page, "c"),
)


def build_app(sync_url: bool = True):
    """The whole lab: a title and one tab per page (a Panel layout).

    Parameters
    ----------
    sync_url : bool
        When served, keep every page's settings and the open tab in the URL
        (``?page=1&l_z_max=0.3``), and read them from it on load.

    Returns
    -------
    panel.Column
        Display it in a notebook, ``.servable()`` it, or serve it with
        ``valve-gym lab``.
    """
    pn.extension(sizing_mode="fixed", loading_indicator=True)
    labs = {}
    tabs = []
    for title, cls, page, prefix in _PAGES:
        lab = cls() if cls is not ValvePage else ValvePage(preset="fig7")
        labs[prefix] = lab
        tabs.append((title, page(lab)))
    tab_widget = pn.Tabs(*tabs, dynamic=True, css_classes=["vg-tabs"])
    if sync_url and pn.state.location is not None:
        loc = pn.state.location
        loc.sync(tab_widget, {"active": "page"})
        for prefix, lab in labs.items():
            names = [p for p in lab.param if p not in ("name", "preset", "reveal")]
            loc.sync(lab, {p: f"{prefix}_{p}" for p in names})
    head = pn.pane.Markdown(
        "## valve_gym teaching lab: control valve friction\n"
        "Set the valve, see its stick-slip; put it in a loop, see the limit cycle; compensate it. "
        "Every setting is in the URL: copy it to share the view.")
    return pn.Column(head, tab_widget, css_classes=["vg-app"])


# --------------------------------------------------------------------------- PNG
def png_bytes(tr: Traces, stem: str, dpi: int = 110) -> bytes:
    """A PNG of the traces (matplotlib, Agg, no browser), the same curves as the page's plots."""
    from ..figures import _figure

    if stem == "valve":
        fig = _figure(11, 6.5)
        ax0 = fig.add_subplot(1, 2, 1)
        ax1 = fig.add_subplot(2, 2, 2)
        ax2 = fig.add_subplot(2, 2, 4, sharex=ax1)
        c = tr.columns
        ax0.plot(c["input"], c["healthy_h"], color="0.6", label="healthy valve")
        ax0.plot(c["input"], c["stem"], color="tab:red", label="this valve")
        ax0.set_xlabel("input i [fraction of stroke]")
        ax0.set_ylabel("stem h [fraction of stroke]")
        ax1.plot(tr.t, c["input"], "--", color="0.3", label="input i")
        ax1.plot(tr.t, c["healthy_h"], color="0.6", label="healthy stem")
        ax1.plot(tr.t, c["stem"], color="tab:red", label="stem h")
        ax2.plot(tr.t, c["friction"], color="tab:red")
        ax2.set_ylabel(f"friction state [{tr.summary['friction_unit']}]")
        ax2.set_xlabel("time [s]")
        for a in (ax0, ax1):
            a.legend(fontsize=8)
    else:
        parts = tr.extra if tr.extra else {"": tr}
        fig = _figure(5.5 * len(parts), 6.5)
        axes = fig.subplots(2, len(parts), squeeze=False, sharex="col")
        for j, (key, sub) in enumerate(parts.items()):
            c = sub.columns
            a1, a2 = axes[0, j], axes[1, j]
            a1.plot(sub.t, c["sp"], "--", color="0.3", label="SP")
            for k, lab, col in (("pv_ghost", "PV, frictionless", "0.6"), ("pv_pi", "PV, PI", "0.6"),
                                ("pv", "PV", "tab:blue")):
                if k in c:
                    a1.plot(sub.t, c[k], color=col, label=lab)
            for k, lab, col in (("op_ghost", "OP, frictionless", "0.6"), ("stem_pi", "stem, PI", "0.6"),
                                ("op", "OP", "tab:orange"), ("stem", "stem", "tab:red")):
                if k in c:
                    a2.plot(sub.t, c[k], color=col, label=lab)
            a1.set_title(key + (" " if key else "") + (fmt_lc(sub.summary) if "lc" in sub.summary else ""),
                         fontsize=10)
            a1.set_ylabel("level / PV")
            a2.set_ylabel("OP, stem [fraction of stroke]")
            a2.set_xlabel("time [s]")
            a1.legend(fontsize=8)
            a2.legend(fontsize=8)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()
