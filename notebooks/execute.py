"""Execute the notebooks in place with their full settings and store their outputs.

    python notebooks/execute.py                      # every notebook in notebooks/
    python notebooks/execute.py 02_reacher.ipynb     # only the ones named
    python notebooks/execute.py --check              # only check the stored notebooks

Every notebook runs top to bottom in a fresh ``python3`` kernel whose working directory is
``notebooks/``, with the full settings (``PILCO_NOTEBOOK_FAST=0``), MuJoCo's headless EGL
renderer (``MUJOCO_GL=egl``) and TensorFlow's C++ logging quietened
(``TF_CPP_MIN_LOG_LEVEL=2``). The repository root is put first on the kernel's
``PYTHONPATH``, so the notebooks run against this checkout's ``pilco``.

The executed notebook is then cleaned before it is written back:

* figures stay as PNG outputs, printed text and tables stay;
* progress-bar debris goes: widget outputs, progress bars, every line a carriage return
  rewrote (what a terminal would show is kept unless it is blank or a progress bar), and
  tqdm's warning that a kernel without ipywidgets gets no progress widget;
* TensorFlow and absl log lines go from stderr outputs;
* machine paths in outputs (this checkout, the Python installation, the home directory,
  the temporary directory) are replaced by ``..``/``<python>``/``~``/``<tmp>``;
* consecutive outputs of one stream are merged, execution counts run 1, 2, 3, ...;
* the notebook's metadata is kept as stored, plus ``metadata.pilco.code_hash``: the hash
  of its code cells' sources (:func:`code_hash`). The test suite compares it with the
  current code cells, so a code cell edited without re-executing fails the tests.

A notebook is written only when it executed without an error and the cleaned result passes
:func:`stored_notebook_problems` (the same check the test suite applies); otherwise the
file is left as it was and the script exits with status 1.
"""
from __future__ import annotations

import argparse
import ast
import copy
import hashlib
import json
import logging
import os
import re
import sys
import sysconfig
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, Iterable, List, Optional

NOTEBOOK_DIR = Path(__file__).resolve().parent
ROOT = NOTEBOOK_DIR.parent

#: environment of the executing kernel (on top of this process's environment)
KERNEL_ENV = {"PILCO_NOTEBOOK_FAST": "0", "MUJOCO_GL": "egl", "TF_CPP_MIN_LOG_LEVEL": "2"}
#: seconds one cell may take before the execution is abandoned
CELL_TIMEOUT = 1800
#: a stored notebook must be smaller than this many bytes
MAX_NOTEBOOK_BYTES = 2_000_000
#: the command that refreshes the stored outputs (quoted in the test failures)
COMMAND = "python notebooks/execute.py"

WIDGET_MIME = "application/vnd.jupyter.widget-view+json"

logger = logging.getLogger("execute")

# A line of a progress bar (tqdm's "45%|####      | 9/20 [00:01<00:02, 4.5it/s]").
_PROGRESS_BAR = re.compile(r"\d+%\|.*\|\s*\d+(\.\d+)?[kMG]?/\d+|\|\s*\d+/\d+ \[\d+:\d+")
# TensorFlow/absl log lines: C++ ("2025-01-02 03:04:05.678901: W tensorflow/...",
# "W0000 00:00:1700000000.123456   123 file.cc:45] ..."), absl's pre-init banner, and
# Python's absl/tensorflow loggers ("WARNING:tensorflow:...").
_LOG_LINES = [
    re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d+: [IWEF] "),
    re.compile(r"^[IWEF]\d{4} \d+:\d+:\d+(\.\d+)?\s+\d+ \S+:\d+\] "),
    re.compile(r"^WARNING: All log messages before absl::InitializeLog\(\) is called"),
    re.compile(r"^(DEBUG|INFO|WARNING|ERROR|CRITICAL):(absl|tensorflow|tf_keras|h5py)[:.]"),
]
# The warning tqdm.auto gives in a kernel without ipywidgets ("<file>:21: TqdmWarning:
# IProgress not found..."), followed by the indented source line Python quotes.
_PROGRESS_WARNING = re.compile(r":\d+: Tqdm\w*Warning: ")
# Absolute paths that belong to a machine rather than to the project.
_MACHINE_PATH = re.compile(
    r"(?<![\w.~])(/home/|/Users/|/root/|/tmp/|/private/|/var/folders/|/usr/local/lib/python"
    r"|/opt/conda|[A-Za-z]:\\(Users|Windows)\\)")


# --------------------------------------------------------------------------- the hash
def _source(cell: Dict[str, Any]) -> str:
    src = cell.get("source", "")
    return src if isinstance(src, str) else "".join(src)


def code_hash(nb: Dict[str, Any]) -> str:
    """``"sha256:<hex>"`` of the notebook's code cells' sources, in order.

    Markdown cells, outputs and metadata do not count: only a change to the code makes the
    stored outputs stale. Works on ``json.load``-ed notebooks (sources as lists of lines) and
    on ``nbformat`` ones (sources as strings) alike.
    """
    digest = hashlib.sha256()
    for cell in nb["cells"]:
        if cell["cell_type"] != "code":
            continue
        data = _source(cell).encode("utf-8")
        digest.update(f"{len(data)}\n".encode("ascii"))
        digest.update(data)
    return "sha256:" + digest.hexdigest()


def stored_code_hash(nb: Dict[str, Any]) -> Optional[str]:
    """The code hash stored by the last execution (``None`` if there is none)."""
    return nb.get("metadata", {}).get("pilco", {}).get("code_hash")


# ------------------------------------------------------------------------ the cleaning
def machine_path_replacements() -> List[tuple]:
    """``(absolute prefix, replacement)`` pairs for this machine, longest prefix first.

    Paths inside the repository become relative to ``notebooks/`` (the kernel's working
    directory); the Python installation, the home and the temporary directory become
    ``<python>``, ``~`` and ``<tmp>``.
    """
    pairs = {
        str(NOTEBOOK_DIR) + os.sep: "",
        str(ROOT) + os.sep: ".." + os.sep,
        str(ROOT): "..",
    }
    for prefix in {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"],
                   sys.prefix, sys.base_prefix, os.path.realpath(sys.prefix)}:
        pairs.setdefault(prefix, "<python>")
    pairs.setdefault(os.path.realpath(tempfile.gettempdir()), "<tmp>")
    pairs.setdefault(tempfile.gettempdir(), "<tmp>")
    home = os.path.expanduser("~")
    if home not in ("", "/", "~"):
        pairs.setdefault(home, "~")
    return sorted(pairs.items(), key=lambda kv: len(kv[0]), reverse=True)


def _scrub_paths(text: str, replacements) -> str:
    for prefix, replacement in replacements:
        text = text.replace(prefix, replacement)
    return text


def _resolve_carriage_returns(line: str) -> str:
    """What a terminal shows of one line: the text after its last carriage return."""
    return line.rstrip("\r").rsplit("\r", 1)[-1]


def clean_stream_text(text: str, stderr: bool) -> str:
    """A stream output's text without progress-bar debris (and log lines, on stderr)."""
    kept = []
    lines = text.split("\n")          # not splitlines(): it splits at "\r" too
    skip_quoted_source = False
    for k, body in enumerate(lines):
        newline = "\n" if k < len(lines) - 1 else ""
        if skip_quoted_source and body.startswith((" ", "\t")):
            continue
        skip_quoted_source = False
        if not body and not newline:
            continue
        if stderr and _PROGRESS_WARNING.search(body):
            skip_quoted_source = True
            continue
        if "\r" in body:
            body = _resolve_carriage_returns(body)
            if not body.strip() or _PROGRESS_BAR.search(body):
                continue
        elif _PROGRESS_BAR.search(body):
            continue
        if stderr and any(p.search(body) for p in _LOG_LINES):
            continue
        kept.append(body + newline)
    return "".join(kept)


def _clean_value(value, replacements):
    if isinstance(value, str):
        return _scrub_paths(value, replacements)
    if isinstance(value, list):
        return [_clean_value(v, replacements) for v in value]
    if isinstance(value, dict):
        return {k: _clean_value(v, replacements) for k, v in value.items()}
    return value


def clean_outputs(outputs: Iterable[Dict[str, Any]], replacements) -> List[Dict[str, Any]]:
    """One cell's outputs, cleaned (see the module docstring); order kept."""
    cleaned: List[Dict[str, Any]] = []
    for output in outputs:
        output = copy.deepcopy(dict(output))
        kind = output["output_type"]
        if kind == "stream":
            text = clean_stream_text(_source({"source": output["text"]}),
                                     stderr=output["name"] == "stderr")
            text = _scrub_paths(text, replacements)
            if not text:
                continue
            if cleaned and cleaned[-1]["output_type"] == "stream" \
                    and cleaned[-1]["name"] == output["name"]:
                cleaned[-1]["text"] += text
                continue
            output["text"] = text
        elif kind in ("display_data", "execute_result"):
            data = output.get("data", {})
            if WIDGET_MIME in data:
                continue
            output["data"] = {mime: (value if mime.startswith("image/") and mime != "image/svg+xml"
                                     else _clean_value(value, replacements))
                              for mime, value in data.items()}
        elif kind == "error":
            output["traceback"] = [_scrub_paths(line, replacements)
                                   for line in output.get("traceback", [])]
        cleaned.append(output)
    return cleaned


def clean_notebook(nb: Dict[str, Any], metadata: Dict[str, Any],
                   replacements=None) -> Dict[str, Any]:
    """The executed notebook `nb` ready to store (a new object; `nb` is not changed).

    `metadata` is the notebook metadata to keep (the stored one, so that the kernel's
    version details and widget state are not written); ``pilco.code_hash`` is set in it.
    """
    if replacements is None:
        replacements = machine_path_replacements()
    out = copy.deepcopy(nb)
    count = 0
    for cell in out["cells"]:
        if cell["cell_type"] != "code":
            continue
        cell.get("metadata", {}).pop("execution", None)
        if cell.get("execution_count") is None:
            cell["outputs"] = clean_outputs(cell.get("outputs", []), replacements)
            continue
        count += 1
        cell["execution_count"] = count
        cell["outputs"] = clean_outputs(cell.get("outputs", []), replacements)
        for output in cell["outputs"]:
            if output["output_type"] == "execute_result":
                output["execution_count"] = count
    out["metadata"] = copy.deepcopy(dict(metadata))
    out["metadata"].pop("widgets", None)
    out["metadata"].setdefault("pilco", {})["code_hash"] = code_hash(out)
    return out


# ------------------------------------------------------------------------ the checks
def _output_texts(output: Dict[str, Any]) -> Iterable[str]:
    kind = output["output_type"]
    if kind == "stream":
        yield _source({"source": output.get("text", "")})
    elif kind in ("display_data", "execute_result"):
        for mime, value in output.get("data", {}).items():
            if mime.startswith("image/") and mime != "image/svg+xml":
                continue
            yield value if isinstance(value, str) else json.dumps(value)
    elif kind == "error":
        yield "\n".join(output.get("traceback", []))


def _code_for_ast(source: str) -> str:
    try:
        from IPython.core.inputtransformer2 import TransformerManager
    except ImportError:
        return source
    return TransformerManager().transform_cell(source)


class _Calls(ast.NodeVisitor):
    """Names of the functions a piece of code calls (``plt.show`` as ``"plt.show"``),
    outside the bodies of the functions and classes it defines; and those definitions."""

    def __init__(self):
        self.calls = set()
        self.defs = {}

    def visit_Call(self, node):
        func = node.func
        if isinstance(func, ast.Name):
            self.calls.add(func.id)
        elif isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name):
            self.calls.add(f"{func.value.id}.{func.attr}")
        self.generic_visit(node)

    def _visit_def(self, node):
        inner = _Calls()
        for statement in node.body:
            inner.visit(statement)
        self.defs[node.name] = inner.calls

    visit_FunctionDef = visit_AsyncFunctionDef = visit_ClassDef = _visit_def


def expected_outputs(nb: Dict[str, Any]) -> Dict[int, set]:
    """Cell index -> what the stored outputs of the cell must include.

    ``{"figure", "output"}`` for a cell that calls ``plt.show()`` (a PNG), ``{"output"}``
    for one that calls ``print()`` (some output: a function that prints on one path may
    show a figure on another), directly or through a function the notebook defines (at any
    depth). A cell that only defines things needs no output. Cells that do not parse as
    Python are left out.
    """
    per_cell: Dict[int, set] = {}
    defs: Dict[str, set] = {}
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] != "code":
            continue
        try:
            tree = ast.parse(_code_for_ast(_source(cell)))
        except SyntaxError:
            continue
        visitor = _Calls()
        visitor.visit(tree)
        per_cell[i] = visitor.calls
        defs.update(visitor.defs)
    effects = {"plt.show": {"figure", "output"}, "print": {"output"}}
    changed = True
    while changed:          # what each notebook function does, through the ones it calls
        changed = False
        for name, calls in defs.items():
            found = set().union(*(effects.get(c, set()) for c in calls))
            if not found <= effects.get(name, set()):
                effects[name] = effects.get(name, set()) | found
                changed = True
    return {i: set().union(*(effects.get(c, set()) for c in calls))
            for i, calls in per_cell.items()}


def stored_notebook_problems(nb: Dict[str, Any], size: Optional[int] = None) -> List[str]:
    """Everything that keeps a stored notebook from showing its current results.

    Checks that the outputs are fresh (``metadata.pilco.code_hash`` equals
    :func:`code_hash`), that every code cell ran (execution counts 1, 2, 3, ... in order)
    without an error, that each cell has the outputs its code produces (a PNG for
    ``plt.show()``, some output for ``print()``, see :func:`expected_outputs`), that no output
    holds progress-bar debris, widgets, TensorFlow/absl log lines or machine paths, and
    that the file (`size` bytes, if given) is smaller than ``MAX_NOTEBOOK_BYTES``.
    """
    problems = []
    stored, current = stored_code_hash(nb), code_hash(nb)
    if stored is None:
        problems.append(f"it has no stored outputs (no metadata.pilco.code_hash): run `{COMMAND}`")
    elif stored != current:
        problems.append(f"its code cells changed since its outputs were stored: run `{COMMAND}`")
    if size is not None and size >= MAX_NOTEBOOK_BYTES:
        problems.append(f"it is {size / 1e6:.2f} MB, the limit is "
                        f"{MAX_NOTEBOOK_BYTES / 1e6:.0f} MB (smaller or fewer figures)")
    if "widgets" in nb.get("metadata", {}):
        problems.append("its metadata holds widget state")
    expected = expected_outputs(nb)
    replacements = [p for p, _ in machine_path_replacements() if len(p) > 1]
    count = 0
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] != "code":
            continue
        where = f"cell {i}"
        outputs = cell.get("outputs", [])
        if not _source(cell).strip():
            continue
        count += 1
        if cell.get("execution_count") != count:
            problems.append(f"{where}: execution count {cell.get('execution_count')}, "
                            f"expected {count} (cells executed in order, once)")
        kinds = {"output"} if outputs else set()
        for output in outputs:
            kind = output["output_type"]
            if kind == "error":
                problems.append(f"{where}: error output ({output.get('ename')}: "
                                f"{output.get('evalue')})")
            elif kind != "stream":
                data = output.get("data", {})
                if "image/png" in data:
                    kinds.add("figure")
                if WIDGET_MIME in data:
                    problems.append(f"{where}: widget output")
            stderr = kind == "stream" and output["name"] == "stderr"
            for text in _output_texts(output):
                if "\r" in text:
                    problems.append(f"{where}: carriage return (progress-bar debris)")
                for line in text.splitlines():
                    if _PROGRESS_BAR.search(line):
                        problems.append(f"{where}: progress bar {line.strip()[:60]!r}")
                    if stderr and any(p.search(line) for p in _LOG_LINES):
                        problems.append(f"{where}: log line {line.strip()[:60]!r}")
                    if stderr and _PROGRESS_WARNING.search(line):
                        problems.append(f"{where}: progress-bar warning {line.strip()[:60]!r}")
                match = _MACHINE_PATH.search(text)
                if match:
                    problems.append(f"{where}: machine path {text[match.start():][:40]!r}")
                for prefix in replacements:
                    if prefix in text:
                        problems.append(f"{where}: machine path {prefix!r}")
        missing = expected.get(i, set()) - kinds
        if "figure" in missing:
            problems.append(f"{where}: no PNG figure although its code shows one")
        elif "output" in missing:
            problems.append(f"{where}: no output although its code prints")
    return problems


# ------------------------------------------------------------------------- executing
def notebook_paths(names: Iterable[str]) -> List[Path]:
    """The notebooks named (file names in ``notebooks/``, with or without ``.ipynb``, or
    paths to them); every notebook in ``notebooks/`` if none is named."""
    names = list(names)
    if not names:
        return sorted(NOTEBOOK_DIR.glob("*.ipynb"))
    paths = []
    for name in names:
        path = Path(name)
        if not path.is_file():
            path = NOTEBOOK_DIR / (name if name.endswith(".ipynb") else name + ".ipynb")
        path = path.resolve()
        if path.parent != NOTEBOOK_DIR or path.suffix != ".ipynb" or not path.is_file():
            raise ValueError(f"{name}: not a notebook in {NOTEBOOK_DIR.name}/")
        paths.append(path)
    return paths


def kernel_environment() -> Dict[str, str]:
    """This process's environment with the full settings and this checkout first on the
    kernel's ``PYTHONPATH``."""
    env = dict(os.environ)
    env.update(KERNEL_ENV)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    return env


def execute_notebook(path: Path, timeout: int = CELL_TIMEOUT) -> bool:
    """Execute `path` in place and store the cleaned result; False (file untouched) on
    an error or a failed check."""
    import nbformat
    from nbclient import NotebookClient
    from nbclient.exceptions import CellExecutionError, CellTimeoutError

    nb = nbformat.read(path, as_version=4)
    metadata = copy.deepcopy(nb.metadata)
    executed_hash = code_hash(nb)
    client = NotebookClient(nb, timeout=timeout, kernel_name="python3", allow_errors=False,
                            record_timing=False,
                            resources={"metadata": {"path": str(NOTEBOOK_DIR)}})
    t0 = time.perf_counter()
    try:
        client.execute(env=kernel_environment())
    except (CellExecutionError, CellTimeoutError) as err:
        logger.error("%s: execution failed, file left as it was:\n%s", path.name,
                     _scrub_paths(str(err), machine_path_replacements()))
        return False
    seconds = time.perf_counter() - t0
    result = nbformat.from_dict(clean_notebook(nb, metadata))
    nbformat.validate(result)
    text = nbformat.writes(result) + "\n"
    problems = stored_notebook_problems(json.loads(text), size=len(text.encode("utf-8")))
    if problems:
        logger.error("%s: executed in %.0f s but not stored:\n  %s", path.name, seconds,
                     "\n  ".join(problems))
        return False
    if code_hash(nbformat.read(path, as_version=4)) != executed_hash:
        logger.error("%s: its code cells were edited during the execution; not stored", path.name)
        return False
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    logger.info("%s: executed in %.0f s, stored (%.0f kB)", path.name, seconds,
                len(text.encode("utf-8")) / 1e3)
    return True


def check_notebook(path: Path) -> bool:
    """Log what :func:`stored_notebook_problems` finds in the stored `path`."""
    with open(path, encoding="utf-8") as f:
        nb = json.load(f)
    problems = stored_notebook_problems(nb, size=path.stat().st_size)
    if problems:
        logger.error("%s:\n  %s", path.name, "\n  ".join(problems))
    else:
        logger.info("%s: outputs stored and current", path.name)
    return not problems


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("notebooks", nargs="*",
                        help="notebooks in notebooks/ to execute (default: all)")
    parser.add_argument("--check", action="store_true",
                        help="do not execute: check the stored notebooks' outputs")
    parser.add_argument("--timeout", type=int, default=CELL_TIMEOUT,
                        help=f"seconds per cell (default {CELL_TIMEOUT})")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.timeout <= 0:
        parser.error(f"--timeout must be positive, got {args.timeout}")
    try:
        paths = notebook_paths(args.notebooks)
    except ValueError as err:
        parser.error(str(err))
    run = check_notebook if args.check else execute_notebook
    failed = [p.name for p in paths if not (run(p) if args.check else run(p, args.timeout))]
    if failed:
        logger.error("failed: %s", ", ".join(failed))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
