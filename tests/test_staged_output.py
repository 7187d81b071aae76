"""Result folders are written as one unit: an interrupt leaves the folder as it was, never half a set."""
import os

import numpy as np
import pytest

from valve_gym._io import staged_folder


def _listing(folder):
    return {n: open(os.path.join(folder, n), "rb").read() for n in sorted(os.listdir(folder))}


def _no_staging_left(parent):
    return [n for n in os.listdir(parent) if n.endswith(".partial")] == []


def test_a_new_folder_appears_whole_or_not_at_all(tmp_path):
    out = tmp_path / "res"
    with pytest.raises(KeyboardInterrupt):
        with staged_folder(out) as stage:
            open(os.path.join(stage, "a.csv"), "w").write("1\n")
            raise KeyboardInterrupt
    assert not out.exists() and _no_staging_left(tmp_path)
    with staged_folder(out) as stage:
        open(os.path.join(stage, "a.csv"), "w").write("1\n")
        open(os.path.join(stage, "index.md"), "w").write("see a.csv\n")
    assert _listing(out) == {"a.csv": b"1\n", "index.md": b"see a.csv\n"} and _no_staging_left(tmp_path)
    umask = os.umask(0)
    os.umask(umask)
    assert os.stat(out).st_mode & 0o777 == 0o777 & ~umask        # the usual mode, not the staging folder's 0700


def test_an_existing_folder_keeps_its_old_set_on_interrupt_and_other_files_on_success(tmp_path):
    out = tmp_path / "res"
    out.mkdir()
    (out / "a.csv").write_text("old\n")
    (out / "index.md").write_text("old index\n")
    (out / "mine.txt").write_text("not ours\n")
    before = _listing(out)
    for exc in (KeyboardInterrupt, RuntimeError):
        with pytest.raises(exc):
            with staged_folder(out, last=("index.md",)) as stage:
                open(os.path.join(stage, "a.csv"), "w").write("new\n")
                raise exc
        assert _listing(out) == before and _no_staging_left(tmp_path)
    with staged_folder(out, last=("index.md",)) as stage:
        open(os.path.join(stage, "index.md"), "w").write("new index\n")
        open(os.path.join(stage, "a.csv"), "w").write("new\n")
    assert _listing(out) == {"a.csv": b"new\n", "index.md": b"new index\n", "mine.txt": b"not ours\n"}
    assert _no_staging_left(tmp_path)


def test_index_files_are_published_last(tmp_path, monkeypatch):
    out = tmp_path / "res"
    out.mkdir()
    order = []
    real = os.replace

    def spy(src, dst):
        order.append(os.path.basename(dst))
        return real(src, dst)

    monkeypatch.setattr(os, "replace", spy)
    with staged_folder(out, last=("results.md",)) as stage:
        for name in ("results.md", "z.png", "a.csv"):
            open(os.path.join(stage, name), "w").write(name)
    assert order == ["a.csv", "z.png", "results.md"]


def _fake_plots(report, monkeypatch, fail_at=None):
    """The report's figures and files as small stand-ins (the wiring is under test, not the plots)."""
    def plot(name):
        def draw(res, path):
            if name == fail_at:
                raise KeyboardInterrupt
            open(path, "w").write(f"{name} of {res}")
            return path
        return draw

    for name in ("overlay", "residuals", "acf", "validation", "stem"):
        monkeypatch.setattr(report, f"plot_{name}", plot(name))
    monkeypatch.setattr(report, "write_json", lambda res, path: plot("json")(res, path))
    monkeypatch.setattr(report, "render_markdown", lambda res, figs: f"report of {res}: {sorted(figs)}")


def test_an_interrupted_diagnosis_report_leaves_the_previous_report(tmp_path, monkeypatch):
    from valve_gym.diagnosis import report

    out = tmp_path / "rep"
    _fake_plots(report, monkeypatch)
    paths = report.write_report("run 1", out)
    assert sorted(os.path.basename(p) for p in paths) == sorted(os.listdir(out))
    assert all(os.path.dirname(p) == str(out) for p in paths)
    assert "report.md" in os.listdir(out) and (out / "report.md").read_text().startswith("report of run 1")
    before = _listing(out)
    _fake_plots(report, monkeypatch, fail_at="acf")
    with pytest.raises(KeyboardInterrupt):
        report.write_report("run 2", out)
    assert _listing(out) == before and _no_staging_left(tmp_path)
    fresh = tmp_path / "fresh"
    with pytest.raises(KeyboardInterrupt):
        report.write_report("run 2", fresh)
    assert not fresh.exists() and _no_staging_left(tmp_path)


def test_an_interrupted_benchmark_writes_no_results(tmp_path, monkeypatch):
    """Ctrl-C while the figures are drawn: no results.md beside missing figures."""
    import valve_gym.agents.bench.cli as bench_cli
    import valve_gym.agents.bench.figures as figs
    import valve_gym.agents.bench.report as rep
    from valve_gym.cli import main as cli_main

    def report(res, out, command=""):
        return (rep._write_text(out / "results.csv", "a\n"), rep._write_text(out / "results.md", "# results\n"))

    def interrupted(res, out):
        np.save(os.path.join(out, "half.npy"), np.zeros(1))
        raise KeyboardInterrupt

    class Result:
        notes = ()

        def jobs_text(self):
            return "1 process"

    monkeypatch.setattr(bench_cli, "run_benchmark", lambda cfg, jobs, progress: Result())
    monkeypatch.setattr(rep, "write_report", report)
    monkeypatch.setattr(figs, "write_figures", interrupted)
    out = tmp_path / "results"
    assert cli_main(["benchmark", "--quick", "--out", str(out), "--jobs", "1", "--no-progress"]) == 130
    assert not out.exists() and _no_staging_left(tmp_path)
    monkeypatch.setattr(figs, "write_figures", lambda res, out: (rep._write_text(out / "trends.png", "png"),))
    assert cli_main(["benchmark", "--quick", "--out", str(out), "--jobs", "1", "--no-progress"]) == 0
    assert sorted(os.listdir(out)) == ["results.csv", "results.md", "trends.png"]


def test_the_diagnosis_tables_keep_any_text_in_its_cell():
    """A failure message with a pipe and a line break left the folder summary's table broken."""
    from valve_gym.diagnosis.report import summary_table

    rows = [{"recording": "loop|a_b", "error": "bad line 3 | col 2\nsecond line"},
            {"recording": "FIC_101", "plant": "tank", "effects": "slip_jump", "stiction": True, "base_rmse": 0.1,
             "final_rmse": 0.05, "base_fit_percent": 50.0, "final_fit_percent": 70.0, "holdout_base_rmse": 0.1,
             "holdout_final_rmse": 0.06, "seconds": 3.0}]
    lines = summary_table(rows).splitlines()
    assert len(lines) == 4                                            # header, rule, one line per row
    assert all(len([c for c in re_cells(line)]) == 10 for line in lines)
    assert "loop\\|a_b" in lines[2] and "ERROR: bad line 3 \\| col 2 second line" in lines[2]
    assert "| FIC_101 | tank | slip_jump |" in lines[3]               # words keep their underscores


def re_cells(line):
    """The cells of a Markdown table row (a pipe behind a backslash is text)."""
    import re

    return re.split(r"(?<!\\)\|", line.strip().strip("|"))
