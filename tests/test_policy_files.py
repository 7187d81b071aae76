"""Model files are safetensors + JSON; pickle-based files are refused and never executed."""
import io
import json
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from valve_gym.agents.safe_files import UnsafeFileError, describe_file, load_model_file, refuse_unsafe, save_model_file

ROOT = Path(__file__).resolve().parents[1]


class _Payload:
    """Unpickling this object creates the marker file (what a malicious policy would do)."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (Path.touch, (Path(self.marker),))


def _pickle_bytes(marker) -> bytes:
    return pickle.dumps({"policy": _Payload(marker)}, protocol=4)


def _crafted_files(tmp_path, marker):
    """Every shape of pickle-based file a user could hand the tool."""
    raw = _pickle_bytes(marker)
    files = {}
    files["raw.pkl"] = tmp_path / "raw.pkl"
    files["raw.pkl"].write_bytes(raw)
    files["proto0.pkl"] = tmp_path / "proto0.pkl"
    files["proto0.pkl"].write_bytes(pickle.dumps(_Payload(marker), protocol=0))
    sb3 = tmp_path / "policy.zip"                    # SB3 layout: data (JSON with pickled parts) + policy.pth
    with zipfile.ZipFile(sb3, "w") as z:
        z.writestr("data", json.dumps({"policy_class": {":serialized:": raw.hex()}}))
        z.writestr("policy.pth", raw)
        z.writestr("valve_gym.json", json.dumps({"name": "evil"}))
    files["policy.zip"] = sb3
    pt = tmp_path / "model.pt"                       # torch.save layout
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("archive/data.pkl", raw)
    pt.write_bytes(buf.getvalue())
    files["model.pt"] = pt
    fake = tmp_path / "fake.safetensors"             # a pickle under the right name, with a JSON beside it
    fake.write_bytes(raw)
    (tmp_path / "fake.json").write_text(json.dumps({"format": "valve_gym.learned_block/1", "hidden": [4]}))
    files["fake.safetensors"] = fake
    return files


def _loaders():
    from valve_gym.agents.es import ESState
    from valve_gym.agents.learned import load_learned
    from valve_gym.agents.ppo import load_policy, read_policy_meta

    return {"load_model_file": load_model_file, "load_learned": load_learned, "load_policy": load_policy,
            "read_policy_meta": read_policy_meta, "es_checkpoint": ESState.load}


def test_crafted_pickles_never_execute(tmp_path):
    marker = tmp_path / "MARKER"
    files = _crafted_files(tmp_path, marker)
    for fname, path in files.items():
        for lname, load in _loaders().items():
            with pytest.raises((UnsafeFileError, ValueError)) as ei:
                load(path)
            msg = str(ei.value)
            assert "\n" not in msg, (fname, lname)
            assert not marker.exists(), f"{lname}({fname}) executed the pickle"
    # the refusal says what the file is and how to convert a trusted one
    with pytest.raises(UnsafeFileError, match=r"stable-baselines3 .zip.*--trust-pickle"):
        refuse_unsafe(files["policy.zip"])
    with pytest.raises(UnsafeFileError, match="Python pickle"):
        refuse_unsafe(files["raw.pkl"])
    assert not marker.exists()


@pytest.mark.slow
def test_cli_refuses_pickles_without_running_them(tmp_path):
    marker = tmp_path / "MARKER"
    files = _crafted_files(tmp_path, marker)
    cfg = ROOT / "configs" / "learned.yaml"
    for path in (files["policy.zip"], files["raw.pkl"], files["fake.safetensors"]):
        out = tmp_path / f"out_{path.stem}"
        r = subprocess.run([sys.executable, "-m", "valve_gym.agents.train", "--config", str(cfg), "--out", str(out),
                            "--resume", str(path), "--no-progress"], capture_output=True, text=True, cwd=ROOT,
                           timeout=120)
        assert r.returncode in (1, 2), r.stderr
        assert "Traceback" not in r.stderr
        assert not marker.exists()


def test_roundtrip_and_corrupt_files(tmp_path):
    w, j = save_model_file(tmp_path / "m", {"a": np.arange(3.0), "b": np.ones((2, 2), np.float32)}, {"x": 1})
    mf = load_model_file(tmp_path / "m.json")
    assert mf.meta == {"x": 1} and np.array_equal(mf.tensors["a"], np.arange(3.0))
    assert describe_file(w) == "safetensors"
    Path(j).write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_model_file(w)
    Path(j).write_text("{}")
    Path(w).write_bytes(b"\x10\x00\x00\x00\x00\x00\x00\x00{broken")
    with pytest.raises(ValueError, match="not a valid safetensors"):
        load_model_file(w)
    Path(j).unlink()
    with pytest.raises(FileNotFoundError, match="m.json"):
        load_model_file(w)


def test_shipped_policies_are_safe_files():
    pol = ROOT / "valve_gym" / "agents" / "policies"
    assert not list(pol.glob("*.zip")) and not list(pol.glob("*.pkl"))
    stems = {p.stem for p in pol.glob("*.safetensors")}
    assert {"learned", "ppo"} <= stems
    for s in stems:
        assert (pol / f"{s}.json").is_file()
        assert describe_file(pol / f"{s}.safetensors") == "safetensors"


def test_convert_policy_is_a_cli_command_and_requires_trust(capsys):
    from valve_gym.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["convert-policy", "--help"])
    assert exc.value.code == 0
    assert "--trust-pickle" in capsys.readouterr().out
    # without the explicit opt-in the conversion refuses to start (bad usage)
    with pytest.raises(SystemExit) as exc:
        main(["convert-policy", "old.zip", "out"])
    assert exc.value.code == 2
