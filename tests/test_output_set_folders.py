"""io/atomic.OutputSet with a folder output (``temp_dir``): replaced whole on commit, untouched on failure."""

from __future__ import annotations

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
