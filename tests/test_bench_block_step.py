"""``benchmarks/bench_block_step.py``: a block's cost per scan, this checkout against another revision."""
from __future__ import annotations

import pytest


def test_one_round_times_every_block_on_both_revisions(repo_module, capsys):
    bench = repo_module("benchmarks/bench_block_step.py", "bench_block_step")
    assert bench.main(["--before", "HEAD", "--steps", "20", "--n", "3", "--repeats", "1"]) == 0
    rows = [r for r in capsys.readouterr().out.splitlines() if r.startswith("| ") and not r.startswith("| block")]
    assert [r.split(" | ")[0].lstrip("| ") for r in rows] == list(bench.NAMES)
    for r in rows:
        cells = [float(c) for c in r.strip("| ").split(" | ")[1:]]
        assert len(cells) == 6 and all(c > 0 for c in cells)


def test_a_revision_git_does_not_know_is_one_clear_error(repo_module, capsys):
    bench = repo_module("benchmarks/bench_block_step.py", "bench_block_step")
    with pytest.raises(SystemExit) as exc:
        bench.main(["--before", "no-such-revision-xyz", "--repeats", "1"])
    assert exc.value.code == 2 and "could not export that revision" in capsys.readouterr().err
