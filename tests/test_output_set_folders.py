"""io/atomic: OutputSet with a folder output (``temp_dir``), replaced whole on commit, untouched on failure;
the logs of failed tool runs that ``logs_kept`` copies out."""

from __future__ import annotations

from pathlib import Path

import pytest

from pwas_hdl.io.atomic import OutputSet


def test_folder_output_replaces_the_old_one_on_commit(tmp_path):
    target = tmp_path / "waves"
    target.mkdir()
    (target / "old.vcd").write_text("old")
    with OutputSet() as outs:
        outs.add(target, "--waves", kind="folder")
        outs.add(tmp_path / "x.csv", "-o")
        staged = outs.temp_dir(target)
        assert staged.parent == tmp_path and staged != target and (target / "old.vcd").exists()
        (staged / "new.vcd").write_text("new")
        outs.write_text(tmp_path / "x.csv", "a\n1\n")
    assert sorted(p.name for p in target.iterdir()) == ["new.vcd"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["waves", "x.csv"]


def test_folder_output_untouched_when_the_command_fails(tmp_path):
    target = tmp_path / "waves"
    target.mkdir()
    (target / "old.vcd").write_text("old")
    with pytest.raises(RuntimeError):
        with OutputSet() as outs:
            outs.add(target, "--waves", kind="folder")
            (outs.temp_dir(target) / "new.vcd").write_text("new")
            raise RuntimeError("the simulation failed")
    assert sorted(p.name for p in target.iterdir()) == ["old.vcd"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["waves"]


def test_new_folder_output_appears_only_on_commit(tmp_path):
    target = tmp_path / "sub" / "waves"
    outs = OutputSet()
    outs.add(target, "--waves", kind="folder")
    (outs.temp_dir(target) / "w.fst").write_text("w")
    assert not target.exists()
    outs.commit()
    assert (target / "w.fst").read_text() == "w"


def test_logs_kept_keeps_the_newest_logs_of_a_name(tmp_path, monkeypatch):
    """Each failed tool run copies its log to $TMPDIR (the error line names it); those copies were
    never removed. Now the newest KEPT_LOGS of a name stay; other names and other files are left."""
    import os
    import tempfile

    from pwas_hdl.errors import ToolFailed
    from pwas_hdl.io.atomic import KEPT_LOGS, logs_kept

    tmpd = tmp_path / "tmpdir"
    tmpd.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmpd))
    old = []
    for k in range(KEPT_LOGS + 5):
        p = tmpd / f"pwas-sim-icarus-old{k:02d}_ab.log"  # mkstemp's form: 8 characters of [a-z0-9_]
        p.write_text(str(k))
        os.utime(p, (1_000_000 + k, 1_000_000 + k))
        old.append(p)
    others = [tmpd / "pwas-synth-ecp5-x1.log", tmpd / "pwas-sim-icarus-notes.txt", tmpd / "mine.log",
              tmpd / "pwas-sim-icarus-run1.log", tmpd / "pwas-sim-icarus-MyRun001.log"]  # not mkstemp's names
    for p in others:
        p.write_text("not ours to remove")
        os.utime(p, (1_000, 1_000))  # older than every kept log
    run = tmp_path / "run"
    run.mkdir()
    (run / "sim.log").write_text("the new log")
    with pytest.raises(ToolFailed) as exc:
        with logs_kept(run, "pwas-sim-icarus"):
            raise ToolFailed("the run failed", run / "sim.log")
    kept = Path(exc.value.log)
    assert kept.parent == tmpd and kept.read_text() == "the new log"
    logs = sorted(p.name for p in tmpd.glob("pwas-sim-icarus-*.log") if p not in others)
    assert len(logs) == KEPT_LOGS and kept.name in logs
    assert [p.exists() for p in old] == [False] * 6 + [True] * (KEPT_LOGS - 1)  # the oldest went
    assert all(p.read_text() == "not ours to remove" for p in others)
