"""Ctrl-C while the ``valve-gym`` command loads the package: one line and exit 130, no traceback."""
from __future__ import annotations

import signal
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


def _run(code: str) -> subprocess.CompletedProcess:
    # SIGINT as a terminal has it (a runner started in the background passes it on ignored)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def test_ctrl_c_while_the_command_loads_the_package_is_one_line():
    # the console script's argv[0]; the package is imported (handler installed) and Ctrl-C arrives
    # before valve_gym.cli.main runs, as in the first two seconds of every valve-gym command
    r = _run("import os, signal, sys, time; sys.argv[0] = '/usr/local/bin/valve-gym'; import valve_gym.cli; "
             "os.kill(os.getpid(), signal.SIGINT); time.sleep(30); print('not stopped')")
    assert r.returncode == 130, (r.returncode, r.stderr)
    assert r.stderr.strip() == "valve-gym: interrupted"
    assert "not stopped" not in r.stdout


def test_the_command_gets_keyboardinterrupt_back_once_loaded():
    r = _run("import signal, sys; sys.argv[0] = '/usr/local/bin/valve-gym'; import valve_gym.cli as c; "
             "loading = signal.getsignal(signal.SIGINT); rc = c.main(['--help']); "
             "print(loading is not signal.default_int_handler, signal.getsignal(signal.SIGINT) is "
             "signal.default_int_handler, rc)")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split()[-3:] == ["True", "True", "0"]


def test_a_program_importing_the_package_keeps_its_handlers():
    r = _run("import signal, sys; sys.argv[0] = 'my_script.py'; import valve_gym; "
             "print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)")
    assert r.returncode == 0 and r.stdout.strip() == "True", r.stderr
    # ignored SIGINT (a background job) stays ignored, even for the command
    r = _run("import signal, sys; signal.signal(signal.SIGINT, signal.SIG_IGN); "
             "sys.argv[0] = '/usr/local/bin/valve-gym'; import valve_gym; "
             "print(signal.getsignal(signal.SIGINT) == signal.SIG_IGN)")
    assert r.returncode == 0 and r.stdout.strip() == "True", r.stderr


def test_worker_processes_of_the_command_keep_python_handlers(tmp_path):
    # a spawned worker gets the command's argv; it must not print the command's line or exit on its own
    script = tmp_path / "probe.py"
    script.write_text("import multiprocessing as mp, signal, sys\n"
                      "def probe():\n"
                      "    import valve_gym\n"
                      "    return signal.getsignal(signal.SIGINT) is signal.default_int_handler\n"
                      "if __name__ == '__main__':\n"
                      "    sys.argv[0] = '/usr/local/bin/valve-gym'\n"
                      "    with mp.get_context('spawn').Pool(1) as p:\n"
                      "        print(p.apply(probe))\n")
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120,
                       preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert r.returncode == 0 and r.stdout.strip() == "True", (r.stdout, r.stderr)
