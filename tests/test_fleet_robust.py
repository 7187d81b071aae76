"""Fleet mode under stress: Ctrl-C at any moment, a partial run (--max-loops), hostile text in the worklist."""
from __future__ import annotations

import html
import os
import re
import signal
import subprocess
import sys
import time

import pytest

import valve_gym
from valve_gym._markdown import md_cell
from valve_gym.diagnosis.synthetic import write_csv
from valve_gym.fleet import FleetSettings, LoopResult, write_worklist
from valve_gym.fleet.simulate import simulate_loop

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(valve_gym.__file__)))
FAST = ["--op-range", "0,100", "--effort", "fast", "--effects", "none", "--jobs", "1"]


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    """Three short loops."""
    d = tmp_path_factory.mktemp("robust") / "recs"
    d.mkdir()
    for i, kind in enumerate(("healthy", "severe", "healthy")):
        write_csv(simulate_loop(kind, seed=i, n=400).recording, d / f"loop{i}.csv")
    return str(d)


# --------------------------------------------------------------------------- Ctrl-C
def _session_processes(sid: int) -> list[str]:
    """``pid command`` of the live processes (not zombies) of session ``sid``, from /proc."""
    out = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/stat") as f:
                stat = f.read()
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()          # after "pid (comm) ": state ppid pgrp session ...
        if int(fields[3]) == sid and fields[0] != "Z":
            out.append(f"{pid} {cmd[:120]}")
    return out


def _command_in_own_session(code: str, args: list[str]) -> tuple[int, str, str, list[str]]:
    """Run ``python -c code *args`` in a session of its own: exit status, stdout, stderr and the processes of
    that session still running 30 s after it exited (then ended, whatever they are)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]))
    env.pop("RAY_ADDRESS", None)
    p = subprocess.Popen([sys.executable, "-c", code, *args], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=True)   # its processes: session p.pid
    try:
        stdout, stderr = p.communicate(timeout=240)
        left = _session_processes(p.pid)
        deadline = time.monotonic() + 30                               # Ray's processes end on their own
        while left and time.monotonic() < deadline:
            time.sleep(0.5)
            left = _session_processes(p.pid)
    finally:
        if p.poll() is None:
            p.kill()
        for line in _session_processes(p.pid):                        # whatever is left is ours: ended
            try:
                os.kill(int(line.split()[0]), signal.SIGKILL)
            except OSError:
                pass
    return p.returncode, stdout, stderr, left


def _stopped_fleet_run(code: str, recs: str, out) -> str:
    """A fleet run of ``recs`` into ``out`` by ``code`` that stops itself: it exits 130 and leaves no process;
    its stderr."""
    rc, stdout, stderr, left = _command_in_own_session(code, ["diagnose", recs, "--out", str(out), *FAST, "--ray"])
    assert not left, f"processes left running after the command exited: {left}"
    assert rc == 130, (stdout + stderr)[-2000:]
    return stderr


#: The command line in a process that presses Ctrl-C on itself while Ray starts: its raylet is up (and
#: starting Ray's agents), the driver not yet connected.
_CTRL_C_WHILE_RAY_STARTS = """
import os, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)   # as in a terminal, whatever the test runner ignores
from ray._private.node import Node
start_raylet = Node.start_raylet
def pressed(self, *a, **k):
    out = start_raylet(self, *a, **k)
    os.kill(os.getpid(), signal.SIGINT)
    return out
Node.start_raylet = pressed
from valve_gym.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads the processes from /proc (Linux)")
def test_ctrl_c_while_ray_starts_stops_cleanly_and_leaves_no_process(recs, tmp_path):
    """A Ctrl-C that cut ``ray.init`` short left Ray's dashboard and runtime-env agents running after the
    command had exited (and once crashed it at exit); now the run stops once Ray is up, shuts it down,
    exits 130 and says what was kept and how to go on."""
    node = pytest.importorskip("ray._private.node")
    if not hasattr(node.Node, "start_raylet"):
        pytest.skip("this Ray version starts its raylet another way")
    out = tmp_path / "fleet"
    stderr = _stopped_fleet_run(_CTRL_C_WHILE_RAY_STARTS, recs, out)
    assert "Traceback" not in stderr, stderr[-2000:]
    last = stderr.strip().splitlines()[-1]
    assert last == (f"valve-gym diagnose: interrupted: 0 loop(s) finished in this run, 0 of 3 in all, are kept in "
                    f"{out / 'loops'}; run the same command again to continue the other 3")
    assert "partial run: 3 of 3 loops not analysed yet" in (out / "worklist.md").read_text()


#: The command line in a process that receives SIGTERM just after Ray's shutdown call, before the command
#: has put its handler back in front: where Ray's core worker had installed its crash handler, its
#: shutdown left SIGTERM to the default action there and the command ended with 143.
_SIGTERM_AS_RAY_SHUTS_DOWN = """
import os, signal, sys, time
import ray
shutdown = ray.shutdown
def shut(*a, **k):
    out = shutdown(*a, **k)
    signal.raise_signal(signal.SIGTERM)
    return out
ray.shutdown = shut
from valve_gym.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads the processes from /proc (Linux)")
def test_sigterm_as_ray_shuts_down_is_noted(recs, tmp_path):
    """Ray's driver starts without its own crash handler, so a SIGTERM while Ray shuts down reaches the
    command's handler: exit 130 with the table and the worklist written, no process left."""
    rc = pytest.importorskip("ray._private.ray_constants")
    if not hasattr(rc, "RAY_DISABLE_FAILURE_SIGNAL_HANDLER"):
        pytest.skip("this Ray version has no switch for its crash handler")
    out = tmp_path / "fleet"
    stderr = _stopped_fleet_run(_SIGTERM_AS_RAY_SHUTS_DOWN, recs, out)
    assert stderr.strip().splitlines()[-1].endswith("every loop had finished, and the table and the worklist are "
                                                     "written")
    assert (out / "loops.csv").is_file() and (out / "worklist.md").is_file()


def test_rays_crash_handler_is_left_out_only_while_ray_starts():
    """The switch is Ray's module constant, set for this process while Ray starts and put back after (a later
    ``ray.init`` of the user's own gets Ray's default)."""
    rc = pytest.importorskip("ray._private.ray_constants")
    if not hasattr(rc, "RAY_DISABLE_FAILURE_SIGNAL_HANDLER"):
        pytest.skip("this Ray version has no switch for its crash handler")
    from valve_gym.fleet.runner import _signals_left_to_python

    before = rc.RAY_DISABLE_FAILURE_SIGNAL_HANDLER
    with _signals_left_to_python():
        assert rc.RAY_DISABLE_FAILURE_SIGNAL_HANDLER is True
    assert rc.RAY_DISABLE_FAILURE_SIGNAL_HANDLER == before


def test_a_signal_is_noted_and_a_handler_ray_would_set_is_not(ctrl_c_as_in_a_terminal):
    """Inside a run a signal sets a flag (the run stops where it is safe), never an exception in the middle
    of Ray's start; ``ray.init`` may not put its own SIGTERM handler in place meanwhile."""
    from valve_gym.fleet.runner import _Stop

    notes: list[str] = []
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with _Stop(notes.append) as stop:
        with stop.kept():
            signal.signal(signal.SIGTERM, lambda s, f: None)           # what ray.init does
            signal.raise_signal(signal.SIGTERM)
            signal.raise_signal(signal.SIGINT)                        # a second signal: nothing more
        assert stop.requested and stop.signum == signal.SIGTERM
        assert len(notes) == 1 and notes[0].startswith("stopping:")
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before


@pytest.fixture
def ctrl_c_as_in_a_terminal():
    """SIGINT raising KeyboardInterrupt, as in a terminal, even where the test runner was started with it ignored."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


def test_ctrl_c_twice_stops_at_once(ctrl_c_as_in_a_terminal):
    """A second Ctrl-C is the way out of a Ray start that hangs: it raises at once, and says what may be left."""
    from valve_gym.fleet.runner import _Stop

    notes: list[str] = []
    with _Stop(notes.append) as stop:
        signal.raise_signal(signal.SIGINT)
        assert stop.requested and "Ctrl-C again to stop at once" in notes[0]
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
    assert len(notes) == 2 and notes[1].startswith("stopping at once") and "ray stop" in notes[1]


# --------------------------------------------------------------------------- --max-loops
def test_max_loops_says_the_run_is_partial_and_how_to_go_on(ray_session, recs, tmp_path, capsys):
    """``--max-loops`` asks for part of the fleet: exit 0, but the summary and the worklist say how many
    loops are left and that the same command continues them; the run that finishes says nothing of it."""
    from valve_gym.diagnosis.cli import main

    out = tmp_path / "fleet"
    argv = ["diagnose", recs, "--out", str(out), *FAST, "--quiet"]
    assert main(argv[1:] + ["--max-loops", "1"]) == 0
    said = capsys.readouterr().out
    assert ("partial run (--max-loops 1): 2 of 3 loops not analysed yet; run the same command again to "
            "continue them") in said.splitlines()
    md = (out / "worklist.md").read_text()
    assert "- partial run: 2 of 3 loops not analysed yet; run the same command again to continue them" in md
    assert "- loops: 3; analysed: 1; failed: 0; not analysed yet: 2" in md
    assert "partial run: 2 of 3 loops" in (out / "worklist.html").read_text()
    assert main(argv[1:] + ["--max-loops", "1"]) == 0                 # the same command goes on
    assert "1 of 3 loops not analysed yet" in capsys.readouterr().out
    assert main(argv[1:]) == 0
    said = capsys.readouterr().out
    assert "partial" not in said and "0 left" in said
    md = (out / "worklist.md").read_text()
    assert "partial" not in md and "- loops: 3; analysed: 3; failed: 0\n" in md


def test_a_signal_while_the_table_and_worklist_are_written_lets_them_finish(ray_session, recs, tmp_path, capsys,
                                                                          monkeypatch):
    """A SIGTERM (a scheduler's stop) while the table and the worklist are written used to end the command with
    143 and no table; now both are written whole, the command exits 130 and says that every loop had finished."""
    from valve_gym.diagnosis.cli import main
    from valve_gym.fleet import runner

    out = tmp_path / "fleet"
    argv = [recs, "--out", str(out), *FAST, "--quiet"]
    assert main(argv) == 0
    for name in ("loops.csv", "loops.parquet", "worklist.md", "worklist.html"):
        (out / name).unlink()
    write_table = runner.write_table

    def stopped_then_written(*a, **k):
        signal.raise_signal(signal.SIGTERM)
        return write_table(*a, **k)

    monkeypatch.setattr(runner, "write_table", stopped_then_written)
    before = signal.getsignal(signal.SIGTERM)
    assert main(argv) == 130                # nothing left to run: only the table and the worklist
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last == (f"valve-gym diagnose: interrupted: 0 loop(s) finished in this run, 3 of 3 in all, are kept in "
                    f"{out / 'loops'}; every loop had finished, and the table and the worklist are written")
    assert "- loops: 3; analysed: 3; failed: 0\n" in (out / "worklist.md").read_text()
    assert len((out / "loops.csv").read_text().strip().splitlines()) == 4
    assert (out / "loops.parquet").stat().st_size > 0 and (out / "worklist.html").stat().st_size > 0
    assert signal.getsignal(signal.SIGTERM) == before                     # put back as it was


# --------------------------------------------------------------------------- Markdown cells
HOSTILE = ("bad | pipe\nsecond line\r\nthird <script>alert(1)</script> `tick *star* _under_ [a](b) ~~s~~ "
           "&amp; back\\slash |")


def _flat(text: str) -> str:
    return " ".join(text.split())


def test_a_hostile_failure_message_leaves_the_worklist_tables_whole(tmp_path):
    """A failure message with a pipe, line breaks, HTML, backticks or ``*`` broke the Markdown table of failed
    loops (the HTML page escaped it); every cell of the fleet's Markdown tables is escaped now."""
    markdown_it = pytest.importorskip("markdown_it")
    rows = [LoopResult(loop="FIC_101", status="failed", message=HOSTILE, action="check the data"),
            LoopResult(loop="LIC*2", status="error", message="x|y", action="check the data"),
            LoopResult(loop="PIC3", status="ok", message=HOSTILE, oscillating=True, score=5.0, weight=0.9,
                       stiction="yes", action="repair <now>")]
    md_path, html_path = write_worklist(rows, [], str(tmp_path), FleetSettings(), top=0)
    md = open(md_path, encoding="utf-8").read()
    page = markdown_it.MarkdownIt("commonmark").enable(["table", "strikethrough"]).render(md)
    failed = page[page.index("Loops that could not be analysed"):]
    table = failed[failed.index("<table>"):failed.index("</table>")]
    body = re.findall(r"<tr>(.*?)</tr>", table[table.index("<tbody>"):], re.S)
    cells = [[html.unescape(c) for c in re.findall(r"<td[^>]*>(.*?)</td>", r, re.S)] for r in body]
    assert cells == [["FIC_101", "failed", _flat(HOSTILE)], ["LIC*2", "error", "x|y"]]
    ranked = page[page.index("<table>"):page.index("</table>")]
    assert "<script>" not in page and "<em>" not in page and "<code>" not in page and "<a href" not in page
    first = re.findall(r"<td[^>]*>(.*?)</td>", ranked[ranked.index("<tbody>"):], re.S)
    assert len(first) == 11 and html.unescape(first[-1]) == _flat(HOSTILE) and first[3] == "repair &lt;now&gt;"
    assert all(line.endswith("|") for line in md.splitlines() if line.startswith("|"))   # every row on one line
    own = open(html_path, encoding="utf-8").read()                     # the page the fleet writes itself
    assert f"<td>{html.escape(_flat(HOSTILE))}</td>" in own and "<td>x|y</td>" in own and "\\|" not in own


@pytest.mark.parametrize("text", [HOSTILE, "no_stiction__2111FIC40102B_0825_0010", "_x_ a_b_ *", "&#x41; &lt; &",
                                  "\\", "a\u2028b\tc", "| | |", "`` ` ``", "$x$ [^1] <http://x>", "w <= 0.33, S < 5 %",
                                  "<!-- c --> </b> <?x?>"])
def test_a_cell_shows_its_text_as_it_is(text):
    markdown_it = pytest.importorskip("markdown_it")
    cell = md_cell(text)
    assert "\n" not in cell and "\r" not in cell
    md = f"| a |\n|---|\n| {cell} |\n"
    page = markdown_it.MarkdownIt("commonmark").enable(["table", "strikethrough"]).render(md)
    tds = re.findall(r"<td[^>]*>(.*?)</td>", page, re.S)
    assert len(tds) == 1 and html.unescape(tds[0]) == _flat(text)
    if ("_" in text and text.replace("_", "").isalnum()) or text.startswith("w <="):
        assert cell == text                                 # a tag's underscores, a comparison: kept readable


def test_any_text_shows_as_it_is_in_the_markdown_and_in_the_html_page():
    """Property: for any text, the rendered cell (CommonMark tables) and the fleet's own HTML cell read the text."""
    markdown_it = pytest.importorskip("markdown_it")
    hyp = pytest.importorskip("hypothesis")
    st = hyp.strategies
    from valve_gym._markdown import md_cells, md_row

    render = markdown_it.MarkdownIt("commonmark").enable(["table", "strikethrough"]).render
    pieces = st.sampled_from(list("ab_ *|\\`<>&#;![]()~$:/\n\t-=x1é") + ["&amp;", "<b>", "http://", "\u2028", "&#65;"])

    @hyp.settings(max_examples=300, deadline=None, database=None)
    @hyp.given(st.lists(pieces, max_size=20).map("".join))
    def shows(text):
        page = render(f"| a | b |\n|---|---|\n{md_row([text, 'z'])}\n")
        tds = re.findall(r"<td[^>]*>(.*?)</td>", page, re.S)
        assert [html.unescape(t) for t in tds] == [_flat(text), "z"]
        assert md_cells(md_row([text, "z"])) == [_flat(text), "z"]

    shows()
