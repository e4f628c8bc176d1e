"""Atomic writes: the target changes only when a write completes; failures leave nothing behind."""

import pytest

from flexmm.io.atomic import atomic_target, write_text_atomic


def test_write_replaces_content_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "config.yaml"
    target.write_text("old")
    write_text_atomic(target, "new")
    assert target.read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["config.yaml"]


def test_failed_write_keeps_the_old_file_and_removes_the_temporary(tmp_path):
    target = tmp_path / "sweep.nc"
    target.write_text("finished result")
    with pytest.raises(RuntimeError):
        with atomic_target(target) as tmp:
            tmp.write_text("half written")
            raise RuntimeError("interrupted")
    assert target.read_text() == "finished result"
    assert [p.name for p in tmp_path.iterdir()] == ["sweep.nc"]
