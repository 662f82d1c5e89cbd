"""Static checks of the notebooks in ``notebooks/`` as stored.

The notebooks are stored executed, with their outputs, so that they show their figures and
numbers when opened; ``python notebooks/execute.py`` executes them with the full settings
and cleans the outputs. These tests check what is stored: outputs for the current code
(``metadata.pilco.code_hash``), from the full settings, in order, without errors, debris or
machine paths, and small enough. They also check that those checks catch what they should.

Executing the notebooks is not done here: ``python -m pytest`` runs every notebook once
through nbmake (see ``pytest.ini`` and the root ``conftest.py``: FAST settings, timeouts,
skips without mujoco, and a failure when a run writes into ``notebooks/``); that run
ignores the stored outputs.
"""
from __future__ import annotations

import copy
import json
import os

import pytest
from _scripts import load_script

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOK_DIR = os.path.join(ROOT, "notebooks")
NOTEBOOKS = sorted(n for n in os.listdir(NOTEBOOK_DIR) if n.endswith(".ipynb"))
REFRESH = "python notebooks/execute.py"
MAX_BYTES = 2_000_000

#: notebook -> modules it must declare in metadata.pilco.requires (skipped without them)
EXPECTED_REQUIREMENTS = {
    "01_moment_matching.ipynb": [],
    "02_reacher.ipynb": ["mujoco", "gymnasium_robotics"],
    "03_damaged_reacher.ipynb": ["mujoco", "gymnasium_robotics"],
    "04_success_rates.ipynb": [],
    "05_multi_target_reacher.ipynb": ["mujoco", "gymnasium_robotics"],
    "06_safe_pilco.ipynb": [],
}
FAST_SWITCH = 'os.environ.get("PILCO_NOTEBOOK_FAST", "0") == "1"'


execute = load_script("_pilco_notebooks_execute", os.path.join(NOTEBOOK_DIR, "execute.py"))


def _load(name):
    with open(os.path.join(NOTEBOOK_DIR, name), encoding="utf-8") as f:
        return json.load(f)


def _source(cell):
    return "".join(cell["source"]) if isinstance(cell["source"], list) else cell["source"]


def _code_cells(nb):
    return [c for c in nb["cells"] if c["cell_type"] == "code"]


def _text(output):
    return "".join(output["text"]) if isinstance(output["text"], list) else output["text"]


# ----------------------------------------------------------------- the stored notebooks
def test_the_notebooks_are_all_known():
    assert NOTEBOOKS == sorted(EXPECTED_REQUIREMENTS)


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_uses_the_python3_kernel_and_has_code(name):
    nb = _load(name)
    assert nb["metadata"]["kernelspec"]["name"] == "python3"
    assert _code_cells(nb), f"{name} has no code cells"


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_stored_outputs_belong_to_the_current_code(name):
    nb = _load(name)
    assert execute.stored_code_hash(nb) == execute.code_hash(nb), (
        f"{name}: its code cells changed since its outputs were stored; run `{REFRESH}` "
        "and commit the executed notebook")


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_stored_outputs_are_complete_and_clean(name):
    path = os.path.join(NOTEBOOK_DIR, name)
    problems = execute.stored_notebook_problems(_load(name), size=os.path.getsize(path))
    assert problems == [], f"{name} (refresh with `{REFRESH}`):\n  " + "\n  ".join(problems)


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_stored_notebook_is_executed_in_order_without_errors(name):
    cells = [c for c in _code_cells(_load(name)) if _source(c).strip()]
    assert [c["execution_count"] for c in cells] == list(range(1, len(cells) + 1))
    errors = [o for c in cells for o in c["outputs"] if o["output_type"] == "error"]
    assert errors == []


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_stored_notebook_shows_its_figures(name):
    cells = _code_cells(_load(name))
    drawing = [c for c in cells if "plt.show()" in _source(c)]
    assert drawing, f"{name} draws no figure"      # every notebook has figures
    pngs = [o for c in cells for o in c["outputs"] if "image/png" in o.get("data", {})]
    assert len(pngs) >= len(drawing)


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_stored_notebook_is_under_2_mb(name):
    assert os.path.getsize(os.path.join(NOTEBOOK_DIR, name)) < MAX_BYTES


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_stored_outputs_come_from_the_full_settings(name):
    """The cell that reads the FAST switch prints it; the stored run must be the full one
    (nbmake's FAST run, e.g. with --overwrite, does not count)."""
    cell = next(c for c in _code_cells(_load(name)) if FAST_SWITCH in _source(c))
    printed = "".join(_text(o) for o in cell["outputs"] if o.get("name") == "stdout")
    assert "FAST=False" in printed


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_has_a_fast_switch(name):
    assert any(FAST_SWITCH in _source(c) for c in _code_cells(_load(name)))


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_declares_its_requirements(name):
    conftest = load_script("_pilco_root_conftest", os.path.join(ROOT, "conftest.py"))
    assert conftest.notebook_requirements(os.path.join(NOTEBOOK_DIR, name)) \
        == EXPECTED_REQUIREMENTS[name]


# --------------------------------------------------------- the checks catch problems
@pytest.fixture
def stored():
    """A stored notebook with figures, cleaned by ``execute.py`` (so that these tests
    check the checks, whatever state the stored files are in)."""
    nb = _load("01_moment_matching.ipynb")
    return execute.clean_notebook(nb, metadata=nb["metadata"])


def _figure_cell(nb):
    return next(c for c in _code_cells(nb) if "plt.show()" in _source(c))


def _printing_cell(nb):
    """The cell that reads the FAST switch: it prints the settings and draws nothing."""
    cell = next(c for c in _code_cells(nb) if FAST_SWITCH in _source(c))
    assert "print(" in _source(cell) and "plt.show()" not in _source(cell)
    return cell


def _add_stream(nb, text, name="stdout"):
    _printing_cell(nb)["outputs"].append({"output_type": "stream", "name": name, "text": text})


def _only(problems, word):
    assert len(problems) >= 1 and all(word in p for p in problems), problems


def test_the_check_passes_a_cleaned_notebook(stored):
    assert execute.stored_notebook_problems(stored) == []


def test_edited_code_cell_is_reported_with_the_refresh_command(stored):
    cell = _code_cells(stored)[-1]
    cell["source"] = _source(cell) + "\nprint('edited')\n"
    problems = execute.stored_notebook_problems(stored)
    assert len(problems) == 1
    assert "code cells changed" in problems[0] and REFRESH in problems[0]


def test_markdown_edits_keep_the_outputs_current(stored):
    markdown = next(c for c in stored["cells"] if c["cell_type"] == "markdown")
    markdown["source"] = _source(markdown) + "\nMore text.\n"
    assert execute.stored_notebook_problems(stored) == []


def test_missing_code_hash_is_reported(stored):
    del stored["metadata"]["pilco"]["code_hash"]
    _only(execute.stored_notebook_problems(stored), "no stored outputs")


def test_cleared_outputs_are_reported(stored):
    for cell in _code_cells(stored):
        cell["outputs"], cell["execution_count"] = [], None
    problems = execute.stored_notebook_problems(stored)
    assert any("no PNG figure" in p or "no output" in p for p in problems)
    assert any("execution count None" in p for p in problems)


def test_missing_figure_is_reported(stored):
    cell = _figure_cell(stored)
    cell["outputs"] = [o for o in cell["outputs"] if "image/png" not in o.get("data", {})]
    _only(execute.stored_notebook_problems(stored), "no PNG figure")


def test_missing_printed_output_is_reported(stored):
    _printing_cell(stored)["outputs"] = []
    _only(execute.stored_notebook_problems(stored), "no output")


def test_error_output_is_reported(stored):
    _printing_cell(stored)["outputs"].append(
        {"output_type": "error", "ename": "ValueError", "evalue": "bad", "traceback": []})
    _only(execute.stored_notebook_problems(stored), "error output (ValueError: bad)")


def test_execution_counts_out_of_order_are_reported(stored):
    cells = _code_cells(stored)
    cells[0]["execution_count"], cells[1]["execution_count"] = 2, 1
    problems = execute.stored_notebook_problems(stored)
    assert len(problems) == 2 and all("execution count" in p for p in problems)


@pytest.mark.parametrize("text, word", [
    (" 45%|####5     | 9/20 [00:01<00:02,  4.50it/s]\r 50%|#####     | 10/20\n", "carriage"),
    ("optimising:  45%|####5     | 9/20 [00:01<00:02,  4.50it/s]\n", "progress bar"),
    ("see /home/alice/pilco/runs/a.npz\n", "machine path"),
    ("saved in /tmp/tmpab12cd/x.npz\n", "machine path"),
    (f"saved in {ROOT}{os.sep}runs\n", "machine path"),
])
def test_debris_in_stdout_is_reported(stored, text, word):
    _add_stream(stored, text)
    problems = execute.stored_notebook_problems(stored)
    assert any(word in p for p in problems), problems


@pytest.mark.parametrize("line", [
    "2025-01-02 03:04:05.678901: I tensorflow/core/platform/cpu_feature_guard.cc:210] AVX2",
    "I0000 00:00:1700000000.123456   12345 port.cc:153] oneDNN custom operations are on.",
    "E0000 00:00:1700000000.123456   12345 cuda_platform.cc:52] failed call to cuInit",
    "WARNING:tensorflow:5 out of the last 5 calls to <function f> triggered retracing.",
])
def test_log_lines_in_stderr_are_reported(stored, line):
    _add_stream(stored, line + "\n", name="stderr")
    _only(execute.stored_notebook_problems(stored), "log line")


def test_progress_bar_warning_in_stderr_is_reported(stored):
    _add_stream(stored, "<python>/tqdm/auto.py:21: TqdmWarning: IProgress not found.\n"
                        "  from .autonotebook import tqdm as notebook_tqdm\n", name="stderr")
    _only(execute.stored_notebook_problems(stored), "progress-bar warning")


def test_widget_output_is_reported(stored):
    _printing_cell(stored)["outputs"].append(
        {"output_type": "display_data", "metadata": {},
         "data": {execute.WIDGET_MIME: {"model_id": "abc", "version_major": 2},
                  "text/plain": "HBox(children=(FloatProgress(value=0.0),))"}})
    _only(execute.stored_notebook_problems(stored), "widget output")


def test_size_over_the_limit_is_reported(stored):
    _only(execute.stored_notebook_problems(stored, size=MAX_BYTES), "the limit is 2 MB")
    assert execute.stored_notebook_problems(stored, size=MAX_BYTES - 1) == []


# ------------------------------------------------------------------------ the cleaning
def test_code_hash_reads_list_and_string_sources_alike(stored):
    as_strings = copy.deepcopy(stored)
    for cell in as_strings["cells"]:
        cell["source"] = _source(cell)
    assert execute.code_hash(as_strings) == execute.code_hash(stored)
    assert execute.code_hash(stored).startswith("sha256:")


def test_code_hash_sees_code_moved_between_cells(stored):
    moved = copy.deepcopy(stored)
    a, b = _code_cells(moved)[:2]
    a["source"], b["source"] = _source(a) + _source(b)[:1], _source(b)[1:]
    assert execute.code_hash(moved) != execute.code_hash(stored)


def test_clean_stream_text_keeps_results_and_drops_debris():
    text = ("FAST=False\n"
            "  0%|          | 0/20 [00:00<?, ?it/s]\r 50%|#####     | 10/20 [00:01<00:01]\r"
            "                                        \r"
            "done\n"
            "train:  100%|##########| 20/20 [00:02<00:00,  9.9it/s]\n"
            "I0000 00:00:1700000000.123456   12345 port.cc:153] oneDNN\n")
    assert execute.clean_stream_text(text, stderr=False) == (
        "FAST=False\ndone\nI0000 00:00:1700000000.123456   12345 port.cc:153] oneDNN\n")
    assert execute.clean_stream_text(text, stderr=True) == "FAST=False\ndone\n"
    assert execute.clean_stream_text("a\rb\n", stderr=False) == "b\n"


def test_clean_stream_text_drops_the_progress_widget_warning():
    text = ("<python>/tqdm/auto.py:21: TqdmWarning: IProgress not found. Please update jupyter\n"
            "  from .autonotebook import tqdm as notebook_tqdm\n"
            "a real warning\n"
            "  kept with its indentation\n")
    assert execute.clean_stream_text(text, stderr=True) == (
        "a real warning\n  kept with its indentation\n")


def test_clean_outputs_merges_streams_drops_widgets_and_scrubs_paths():
    replacements = [(f"{NOTEBOOK_DIR}{os.sep}", ""), (f"{ROOT}{os.sep}", f"..{os.sep}")]
    png = "iVBORw0KGgo="
    outputs = [
        {"output_type": "stream", "name": "stdout", "text": f"wrote {NOTEBOOK_DIR}{os.sep}a.npz\n"},
        {"output_type": "stream", "name": "stdout", "text": f"read {ROOT}{os.sep}pilco\n"},
        {"output_type": "stream", "name": "stderr",
         "text": "2025-01-02 03:04:05.678901: W tensorflow/x.cc:1] noise\n"},
        {"output_type": "display_data", "metadata": {},
         "data": {execute.WIDGET_MIME: {"model_id": "abc"}, "text/plain": "HBox()"}},
        {"output_type": "display_data", "metadata": {},
         "data": {"image/png": png, "text/plain": "<Figure size 640x480 with 1 Axes>"}},
    ]
    cleaned = execute.clean_outputs(outputs, replacements)
    assert cleaned == [
        {"output_type": "stream", "name": "stdout",
         "text": f"wrote a.npz\nread ..{os.sep}pilco\n"},
        {"output_type": "display_data", "metadata": {},
         "data": {"image/png": png, "text/plain": "<Figure size 640x480 with 1 Axes>"}},
    ]


def test_clean_notebook_numbers_cells_and_stores_the_hash(stored):
    executed = copy.deepcopy(stored)
    executed["metadata"]["widgets"] = {"state": {}}
    executed["metadata"]["language_info"]["version"] = "3.11.9"
    for k, cell in enumerate(_code_cells(executed)):
        cell["execution_count"] = 10 + 2 * k
        cell["metadata"]["execution"] = {"iopub.status.busy": "2025-01-02T03:04:05Z"}
    _add_stream(executed, "  5%|5         | 1/20 [00:00<00:05]\r\n", name="stderr")
    last = _code_cells(executed)[-1]
    last["source"] = _source(last) + "\n# changed\n"
    cleaned = execute.clean_notebook(executed, metadata=stored["metadata"])
    assert [c["execution_count"] for c in _code_cells(cleaned)] \
        == list(range(1, len(_code_cells(cleaned)) + 1))
    assert all("execution" not in c["metadata"] for c in _code_cells(cleaned))
    assert "widgets" not in cleaned["metadata"]
    assert "version" not in cleaned["metadata"]["language_info"]
    assert cleaned["metadata"]["pilco"]["code_hash"] == execute.code_hash(executed) \
        != execute.code_hash(stored)
    assert execute.stored_notebook_problems(cleaned) == []
    assert executed["metadata"]["widgets"] == {"state": {}}      # the input is not changed


def test_notebook_paths_accept_names_and_reject_other_files():
    every = execute.notebook_paths([])
    assert [p.name for p in every] == NOTEBOOKS
    assert execute.notebook_paths(["02_reacher"]) == execute.notebook_paths(
        [os.path.join(NOTEBOOK_DIR, "02_reacher.ipynb")])
    with pytest.raises(ValueError, match="not a notebook"):
        execute.notebook_paths(["no_such_notebook"])
    with pytest.raises(ValueError, match="not a notebook"):
        execute.notebook_paths([os.path.join(ROOT, "setup.py")])


def test_kernel_environment_uses_the_full_settings_and_this_checkout():
    env = execute.kernel_environment()
    assert env["PILCO_NOTEBOOK_FAST"] == "0"
    assert env["MUJOCO_GL"] == "egl"
    assert env["TF_CPP_MIN_LOG_LEVEL"] == "2"
    assert env["PYTHONPATH"].split(os.pathsep)[0] == ROOT
