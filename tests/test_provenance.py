"""Provenance of a run: the git commit and dirty flag, the CPU, the arithmetic settings."""
from __future__ import annotations

import shutil
import subprocess

import pytest

from pilco.experiment import provenance as prov


@pytest.mark.skipif(shutil.which("git") is None, reason="needs git")
def test_git_commit_and_dirty_flag(tmp_path):
    def git(*args):
        return subprocess.run(("git", "-c", "user.name=t", "-c", "user.email=t@t", *args),
                              cwd=tmp_path, check=True, capture_output=True,
                              text=True).stdout.strip()

    assert prov.git_commit(str(tmp_path)) is None  # not a checkout
    git("init", "-q")
    (tmp_path / "a.txt").write_text("1")
    git("add", "a.txt")
    git("commit", "-qm", "one")
    sha = git("rev-parse", "HEAD")
    assert prov.git_commit(str(tmp_path)) == {"commit": sha, "dirty": False}
    (tmp_path / "new.txt").write_text("untracked files do not count")
    assert prov.git_commit(str(tmp_path))["dirty"] is False
    (tmp_path / "a.txt").write_text("2")
    assert prov.git_commit(str(tmp_path)) == {"commit": sha, "dirty": True}


def test_environment_is_read_per_call(monkeypatch):
    monkeypatch.delenv("TF_ENABLE_ONEDNN_OPTS", raising=False)
    assert "TF_ENABLE_ONEDNN_OPTS" not in prov.provenance()["environment"]
    monkeypatch.setenv("TF_ENABLE_ONEDNN_OPTS", "0")
    p = prov.provenance()
    assert p["environment"]["TF_ENABLE_ONEDNN_OPTS"] == "0"
    assert p["cpu"] == prov.cpu_model() and p["versions"]["pilco"]
