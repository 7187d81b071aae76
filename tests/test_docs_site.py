"""The documentation site builds with warnings as errors, and its API reference holds the documented objects."""
from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _hooks():
    spec = importlib.util.spec_from_file_location("valve_gym_docs_hooks", ROOT / "docs" / "_hooks.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    pytest.importorskip("mkdocs", reason="the [docs] extra is not installed")
    pytest.importorskip("mkdocstrings_handlers.python", reason="the [docs] extra is not installed")
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout}\n{proc.stderr}"
    return out


def test_strict_build_writes_every_nav_page(site):
    from mkdocs.config import load_config

    def pages(nav):
        for item in nav:
            value = next(iter(item.values())) if isinstance(item, dict) else item
            if isinstance(value, list):
                yield from pages(value)
            else:
                yield value

    cfg = load_config(str(ROOT / "mkdocs.yml"))
    missing = [p for p in pages(cfg["nav"])
               if not (site / ("index.html" if p == "index.md" else p[:-3] + "/index.html")).is_file()]
    assert missing == []


@pytest.mark.parametrize("page, anchor", [
    ("api/core", "valve_gym.core.simulate"),
    ("api/plant", "valve_gym.plant.Plant"),
    ("api/envs", "valve_gym.envs.ValveTankEnv"),
    ("api/controllers", "valve_gym.agents.controllers.load_controller"),
    ("api/diagnosis", "valve_gym.diagnosis.diagnose.diagnose"),
    ("api/fleet", "valve_gym.fleet.run_fleet"),
])
def test_api_reference_documents_the_public_objects(site, page, anchor):
    html = (site / page / "index.html").read_text(encoding="utf-8")
    assert f'id="{anchor}"' in html


def test_changelog_page_is_the_changelog(site):
    html = (site / "changelog" / "index.html").read_text(encoding="utf-8")
    assert "0.1.0" in html and "valve_gym.agents" in html


def test_links_out_of_docs_become_repository_paths():
    hooks = _hooks()

    class Page:
        class file:
            src_uri = "controllers.md"

    md = ("see [the data](../valve_gym/data/README.md), [fleet](fleet.md#ray), "
          "[valve_gym/x.py](../valve_gym/x.py), ![fig](figures/a.png) and [web](https://example.org)\n"
          "```\n[in code](../keep.md)\n```")
    out = hooks.on_page_markdown(md, Page, None, None)
    assert "the data (`valve_gym/data/README.md` in the repository)" in out
    assert "[fleet](fleet.md#ray)" in out and "![fig](figures/a.png)" in out
    assert "`valve_gym/x.py`" in out and "(../valve_gym/x.py)" not in out
    assert "[web](https://example.org)" in out and "[in code](../keep.md)" in out


def test_sphinx_roles_are_dropped_from_the_api_pages(site):
    html = (site / "api" / "core" / "index.html").read_text(encoding="utf-8")
    assert "simulate" in html and re.search(r":(func|class|mod|meth|data):<code", html) is None
    hooks = _hooks()
    assert hooks.on_page_content(":func:<code>~valve_gym.metrics.travel</code> a:b", None, None, None) == \
        "<code>valve_gym.metrics.travel</code> a:b"
