import os
import stat

from bayesplate.io import atomic_write_text


def test_atomic_write_gives_usual_permissions_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "a" / "out.md"
    atomic_write_text(target, "hello")
    assert target.read_text() == "hello"
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask
    assert [p.name for p in target.parent.iterdir()] == ["out.md"]
