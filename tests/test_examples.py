"""The README's "Train your own agent" example runs end to end on a tiny budget."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_train_agent_example_trains_exports_and_scores(tmp_path):
    env = {**os.environ, "TRAIN_STEPS": "2048", "QUICK": "1", "OMP_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, str(ROOT / "docs" / "examples" / "train_agent.py")], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert (tmp_path / "my_ppo.safetensors").is_file() and (tmp_path / "my_ppo.json").is_file()
    rows = [ln for ln in r.stdout.splitlines() if " R = " in ln]
    labels = [ln.split(" R = ")[0].strip() for ln in rows]
    assert "my PPO" in labels and "PI (SIMC)" in labels and "knocker" in labels


def test_readme_shows_the_example_that_runs():
    """The README's training tour is docs/examples/train_agent.py (less its first line), so the test above runs it."""
    code = (ROOT / "docs" / "examples" / "train_agent.py").read_text(encoding="utf-8").split("\n", 1)[1].lstrip("\n")
    assert "```python\n" + code + "```" in (ROOT / "README.md").read_text(encoding="utf-8")
