"""The test suite's own set-up: the slowest files handed to the pytest-xdist workers
first (the root ``conftest.py``'s ``SLOW_FILES``, with ``--no-loadscope-reorder`` in
``pytest.ini``)."""
from __future__ import annotations

import configparser
import os

from _scripts import load_script

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
suite = load_script("_pilco_root_conftest", os.path.join(ROOT, "conftest.py"))


class _Item:
    def __init__(self, path):
        self.path = os.path.join(ROOT, path)


def test_every_slow_file_exists_once():
    # a renamed file would silently drop out of the order
    missing = [p for p in suite.SLOW_FILES if not os.path.isfile(os.path.join(ROOT, p))]
    assert missing == []
    assert len(set(suite.SLOW_FILES)) == len(suite.SLOW_FILES)


def test_slow_files_come_first_and_the_rest_keep_their_order():
    names = ["tests/test_rewards.py", suite.SLOW_FILES[1], "tests/test_command.py",
             suite.SLOW_FILES[0], suite.SLOW_FILES[1]]
    items = [_Item(p) for p in names]
    ranks = [suite._slow_rank(item) for item in items]
    assert ranks == [len(suite.SLOW_FILES), 1, len(suite.SLOW_FILES), 0, 1]
    ordered = sorted(items, key=suite._slow_rank)
    assert [os.path.relpath(i.path, ROOT) for i in ordered] == [
        suite.SLOW_FILES[0], suite.SLOW_FILES[1], suite.SLOW_FILES[1],
        "tests/test_rewards.py", "tests/test_command.py"]
    assert [i for i in ordered if i.path.endswith(suite.SLOW_FILES[1])] == [
        items[1], items[4]]  # stable: the order inside a file is kept
    assert suite._slow_rank(_Item("/elsewhere/test_x.py")) == len(suite.SLOW_FILES)


def test_xdist_keeps_the_collection_order():
    ini = configparser.ConfigParser()
    ini.read(os.path.join(ROOT, "pytest.ini"))
    options = ini["pytest"]["addopts"].split()
    assert "--no-loadscope-reorder" in options and "loadfile" in options
