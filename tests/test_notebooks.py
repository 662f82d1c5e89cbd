"""Static checks of the notebooks in ``notebooks/`` as committed.

Executing them is not done here: ``python -m pytest`` runs every notebook once through
nbmake (see ``pytest.ini`` and the root ``conftest.py``: FAST settings, timeouts, skips
without mujoco, and a failure when a run writes into ``notebooks/``). These tests check
what nbmake does not: the committed files carry no outputs, use the ``python3`` kernel,
read the FAST switch, and declare the modules they need.
"""
from __future__ import annotations

import importlib.util
import json
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOK_DIR = os.path.join(ROOT, "notebooks")
NOTEBOOKS = sorted(n for n in os.listdir(NOTEBOOK_DIR) if n.endswith(".ipynb"))

#: notebook -> modules it must declare in metadata.pilco.requires (skipped without them)
EXPECTED_REQUIREMENTS = {
    "01_moment_matching.ipynb": [],
    "02_reacher.ipynb": ["mujoco", "gymnasium_robotics"],
    "03_damaged_reacher.ipynb": ["mujoco", "gymnasium_robotics"],
}


def _load(name):
    with open(os.path.join(NOTEBOOK_DIR, name), encoding="utf-8") as f:
        return json.load(f)


def _root_conftest():
    spec = importlib.util.spec_from_file_location("_pilco_root_conftest",
                                                  os.path.join(ROOT, "conftest.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def output_problems(nb) -> list:
    """What keeps a notebook from counting as 'outputs cleared' (empty when it is)."""
    problems = []
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] != "code":
            continue
        if cell.get("outputs"):
            problems.append(f"cell {i} has outputs")
        if cell.get("execution_count") is not None:
            problems.append(f"cell {i} has an execution count")
    return problems


def test_the_notebooks_are_all_known():
    assert NOTEBOOKS == sorted(EXPECTED_REQUIREMENTS)


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_committed_without_outputs(name):
    nb = _load(name)
    assert nb["metadata"]["kernelspec"]["name"] == "python3"
    assert any(c["cell_type"] == "code" for c in nb["cells"]), f"{name} has no code cells"
    assert output_problems(nb) == [], f"{name}: clear the outputs before committing"


def test_output_check_detects_outputs():
    nb = _load(NOTEBOOKS[0])
    cell = next(c for c in nb["cells"] if c["cell_type"] == "code")
    cell["outputs"] = [{"output_type": "stream", "name": "stdout", "text": ["hi\n"]}]
    cell["execution_count"] = 1
    assert len(output_problems(nb)) == 2


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_has_a_fast_switch(name):
    code = ["".join(c["source"]) for c in _load(name)["cells"] if c["cell_type"] == "code"]
    assert any('os.environ.get("PILCO_NOTEBOOK_FAST", "0") == "1"' in src for src in code)


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_declares_its_requirements(name):
    conftest = _root_conftest()
    assert conftest.notebook_requirements(os.path.join(NOTEBOOK_DIR, name)) \
        == EXPECTED_REQUIREMENTS[name]

