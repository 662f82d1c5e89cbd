"""The documentation says what the code does: every module, file, command and flag named
in README.md and docs/*.md exists, every task is listed where the tasks are listed, and
the README's figures are the ones ``results/`` gives.

What is checked, and how:

- module names (``pilco.xxx.yyy``, in code or prose): the longest importable module of
  the name is imported and the rest are attributes of it (``pilco.tasks.TASKS``);
- repository paths (``pilco/...``, ``examples/...``, ``tests/...``, ``benchmarks/...``,
  ``results/...``, ``notebooks/...``, ``docs/...``) without placeholders exist;
  ``pilco/Name-vN`` is an environment id and must be registered by :mod:`pilco.envs`;
- commands, in inline code and shell blocks: ``pilco COMMAND``, ``python -m pilco[.x]``
  and ``python SCRIPT.py``; the command must exist, and every ``--flag`` given to it must
  be one of that command's parser's options (``pilco run TASK`` and ``examples/TASK.py``:
  the task's, any task's for a placeholder; ``pilco sweep``: the sweep's before ``--``,
  the task's after it and as ``--set``/``--grid`` keys; a script's own ``add_argument``
  flags). A flag named alone in prose must be an option of some command of the project;
- the tasks of :data:`pilco.tasks.TASKS`: each has its example in the README's task table
  and in the guide's examples table, and is named in the README's ``pilco tasks``
  sentence, in the guide's ``pilco run TASK`` sentence and in docs/sweep.md's ``TASK``
  row;
- the README's success table is what ``results/build.py render`` makes of ``results/``,
  and the XLA figures in its Performance section are those of the table's XLA row.
"""
from __future__ import annotations

import argparse
import importlib
import re
import shlex
from functools import lru_cache
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Set, Tuple

import pytest

from pilco import command
from pilco.tasks import TASKS, build_parser as task_parser

ROOT = Path(__file__).resolve().parent.parent
DOCS = ["README.md", *sorted(f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md"))]

#: flags of other tools that the docs name alone, with whose they are
FOREIGN_FLAGS = {"--overwrite": "nbmake's (the suite refuses it)"}
#: files of other repositories that the docs name, with whose they are
FOREIGN_PATHS = {"examples/pendulum_swing_up.py": "the reference port's (nrontsis/PILCO)"}
#: commands of other tools: neither they nor their flags are checked
FOREIGN_COMMANDS = ("pip", "ray", "git", "python3 -m venv", "python -m pytest", "pytest",
                    "python -m venv", ".", "cd", "export", "source")

FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9]*(?:-[a-z0-9]+)*")
MODULE = re.compile(r"(?<![\w./-])pilco(?:\.[A-Za-z_]\w*)+")
PATH = re.compile(r"(?<![\w./-])(?:pilco|examples|tests|benchmarks|results|notebooks|docs)"
                  r"/[\w./-]*[\w/]")
ENV_ID = re.compile(r"^pilco/[A-Z]\w*-v\d+$")


# -- reading the docs ---------------------------------------------------------------------
def _text(doc: str) -> str:
    return (ROOT / doc).read_text(encoding="utf-8")


def _blocks(text: str) -> List[Tuple[str, str]]:
    """``[(language, body)]`` of the fenced code blocks."""
    return re.findall(r"^```(\w*)\n(.*?)^```", text, flags=re.S | re.M)


def _prose(text: str) -> str:
    """The text without its fenced code blocks."""
    return re.sub(r"^```\w*\n.*?^```", "", text, flags=re.S | re.M)


def _spans(text: str) -> List[str]:
    """The inline code spans of the prose (a table cell's ``\\|`` is a ``|``)."""
    return [s.replace("\\|", "|") for s in re.findall(r"`([^`\n]+)`", _prose(text))]


def _lines(doc: str) -> Iterator[Tuple[str, int]]:
    """``(snippet, line number)`` of every inline code span and every line of a shell
    block: the places a command or a flag is written."""
    text = _text(doc)
    for number, line in enumerate(text.splitlines(), start=1):
        for span in re.findall(r"`([^`\n]+)`", line):
            yield span.replace("\\|", "|"), number
    for match in re.finditer(r"^```(\w*)\n(.*?)^```", text, flags=re.S | re.M):
        if match.group(1) not in ("bash", "sh", "shell", ""):
            continue
        first = text.count("\n", 0, match.start(2)) + 1
        for k, line in enumerate(match.group(2).splitlines()):
            if line.strip() and not line.lstrip().startswith("#"):
                yield line, first + k


# -- the project's parsers ----------------------------------------------------------------
def _options(parser: argparse.ArgumentParser) -> Set[str]:
    return {s for action in parser._actions for s in action.option_strings}


@lru_cache(maxsize=None)
def _task_options(task: Optional[str]) -> frozenset:
    """The flags of ``task``; of any task for None (a placeholder such as ``TASK``)."""
    if task is not None:
        return frozenset(_options(task_parser(task)))
    return frozenset(set().union(*(_options(task_parser(name)) for name in TASKS)))


@lru_cache(maxsize=None)
def _sweep_options() -> frozenset:
    from pilco.sweep.cli import build_parser

    return frozenset(_options(build_parser()))


@lru_cache(maxsize=None)
def _diagnose_options() -> frozenset:
    from pilco.diagnose.cli import build_parser

    return frozenset(_options(build_parser()))


TOP_OPTIONS = frozenset({"-h", "--help", "-V", "--version"})


@lru_cache(maxsize=None)
def _script_options(path: str) -> frozenset:
    """The flags a script declares with ``add_argument`` (read from its source)."""
    source = (ROOT / path).read_text(encoding="utf-8")
    calls = re.findall(r"add_argument\((.*?)\)", source, flags=re.S)
    return frozenset({"-h", "--help"} | {flag for call in calls
                                         for flag in re.findall(r"[\"'](--[\w-]+)[\"']", call)})


@lru_cache(maxsize=None)
def _every_option() -> frozenset:
    scripts = [str(p.relative_to(ROOT)) for folder in ("examples", "benchmarks", "results",
                                                       "notebooks")
               for p in (ROOT / folder).glob("*.py")]
    return frozenset(set(_task_options(None)) | _sweep_options() | _diagnose_options()
                     | TOP_OPTIONS | set().union(*(_script_options(s) for s in scripts)))


# -- commands -----------------------------------------------------------------------------
def _words(snippet: str) -> List[str]:
    try:
        return shlex.split(snippet, comments=True)
    except ValueError:  # an unbalanced quote in prose
        return snippet.split()


def _flags(words: List[str]) -> List[str]:
    return [w.split("=", 1)[0] for w in words if FLAG.fullmatch(w.split("=", 1)[0])]


def _task_of(word: Optional[str]) -> Optional[str]:
    return word if word in TASKS else None


def _check_task_flags(words: List[str], task: Optional[str], where: str) -> List[str]:
    known = _task_options(task)
    return [f"{where}: {flag} is not a flag of {f'pilco run {task}' if task else 'any task'}"
            for flag in _flags(words) if flag not in known]


def _check_sweep(words: List[str], where: str) -> List[str]:
    cut = words.index("--") if "--" in words else len(words)
    own, extra = words[:cut], words[cut + 1:]
    task = _task_of(own[0] if own else None)
    problems = [f"{where}: {flag} is not a flag of pilco sweep"
                for flag in _flags(own) if flag not in _sweep_options()]
    for k, word in enumerate(own[:-1]):
        if word in ("--set", "--grid") and "=" in own[k + 1]:
            key = "--" + own[k + 1].split("=", 1)[0].replace("_", "-")
            if key not in _task_options(task):
                problems.append(f"{where}: {word} {own[k + 1]}: {key} is not a flag of "
                                f"{f'pilco run {task}' if task else 'any task'}")
    return problems + _check_task_flags(extra, task, where)


def _check_pilco(words: List[str], where: str) -> List[str]:
    """``words``: the arguments of ``pilco``."""
    if not words:
        return []
    head, rest = words[0], words[1:]
    if head.startswith("-"):
        return [] if head in TOP_OPTIONS else [f"{where}: pilco has no option {head}"]
    if head not in command.COMMANDS:
        return [f"{where}: pilco has no command {head!r} (it has "
                f"{', '.join(command.COMMANDS)})"]
    if head == "run":
        return _check_task_flags(rest, _task_of(rest[0] if rest else None), where)
    if head == "sweep":
        return _check_sweep(rest, where)
    if head == "diagnose":
        return [f"{where}: {flag} is not a flag of pilco diagnose"
                for flag in _flags(rest) if flag not in _diagnose_options()]
    return [f"{where}: pilco tasks takes no flag {flag}" for flag in _flags(rest)
            if flag not in ("-h", "--help")]


#: ``python -m MODULE`` -> the ``pilco`` command it is
MODULE_COMMANDS = {"pilco": [], "pilco.tasks": ["run"], "pilco.sweep": ["sweep"],
                   "pilco.diagnose": ["diagnose"]}


def _check_command(snippet: str, where: str) -> Tuple[Optional[str], List[str]]:
    """``(what it is, problems)`` of a code span or shell line: ``"ours"`` for a command
    of the project, ``"foreign"`` for another tool's, None for anything else."""
    words = _words(snippet)
    while words and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", words[0]):  # VAR=value cmd
        words = words[1:]
    text = " ".join(words)
    if not words:
        return None, []
    if any(text == c or text.startswith(c + " ") for c in FOREIGN_COMMANDS):
        return "foreign", []
    if words[0] == "pilco" and (len(words) == 1 or words[1] in command.COMMANDS
                                or words[1].startswith("-")):
        return "ours", _check_pilco(words[1:], where)
    if words[0] != "python":
        return None, []
    if words[1:2] == ["-m"] and len(words) > 2 and words[2].split(".")[0] == "pilco":
        module = words[2]
        if module not in MODULE_COMMANDS:
            return "ours", [f"{where}: python -m {module}: no such command (the commands are "
                          f"{', '.join(f'python -m {m}' for m in MODULE_COMMANDS)})"]
        return "ours", _check_pilco(MODULE_COMMANDS[module] + words[3:], where)
    if len(words) > 1 and words[1].endswith(".py"):
        script = words[1]
        if not (ROOT / script).is_file():
            return "ours", [f"{where}: python {script}: no such script"]
        name = Path(script).stem
        if script.startswith("examples/") and name in TASKS:
            return "ours", _check_task_flags(words[2:], name, where)
        return "ours", [f"{where}: {flag} is not a flag of {script}"
                      for flag in _flags(words[2:]) if flag not in _script_options(script)]
    return None, []


# -- the checks ---------------------------------------------------------------------------
@pytest.mark.parametrize("doc", DOCS)
def test_every_command_and_flag_named_exists(doc):
    problems = []
    for snippet, number in _lines(doc):
        where = f"{doc}:{number}: `{snippet.strip()}`"
        kind, found = _check_command(snippet, where)
        problems += found
        if kind is not None:
            continue
        for flag in _flags(_words(snippet)):
            if flag not in _every_option() and flag not in FOREIGN_FLAGS:
                problems.append(f"{where}: {flag} is not a flag of any pilco command or "
                                f"script")
    assert not problems, "\n".join(["flags or commands the code does not have:", *problems])


def _resolves(name: str) -> bool:
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            target = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for attribute in parts[cut:]:
            if not hasattr(target, attribute):
                return False
            target = getattr(target, attribute)
        return True
    return False


@pytest.mark.parametrize("doc", DOCS)
def test_every_module_and_path_named_exists(doc):
    import gymnasium

    import pilco.envs  # noqa: F401 - registers the environments

    problems = []
    for number, line in enumerate(_text(doc).splitlines(), start=1):
        for name in MODULE.findall(line):
            if not _resolves(name):
                problems.append(f"{doc}:{number}: {name}: no such module or attribute")
        for path in PATH.findall(line.replace("\\|", "|")):
            if ENV_ID.match(path):
                if path not in gymnasium.envs.registry:
                    problems.append(f"{doc}:{number}: {path}: no such environment id")
            elif re.search(r"[A-Z]{3,}|[<>{}*]", path) or path in FOREIGN_PATHS:
                continue  # TASK, NAME, <task>: placeholders
            elif not (ROOT / path).exists():
                problems.append(f"{doc}:{number}: {path}: no such file or directory")
    assert not problems, "\n".join(["names the code does not have:", *problems])


def _table(text: str, header: str) -> str:
    """The Markdown table whose header line starts with ``header``."""
    start = text.index(header)
    lines = []
    for line in text[start:].splitlines():
        if not line.startswith("|"):
            break
        lines.append(line)
    return "\n".join(lines)


def _paragraph(text: str, words: str) -> str:
    start = text.index(words)
    return text[text.rfind("\n\n", 0, start):text.find("\n\n", start)]


@pytest.mark.parametrize("doc, where, part", [
    ("README.md", "the task table", lambda t: _table(t, "| task | command |")),
    ("README.md", "the `pilco tasks` sentence", lambda t: _paragraph(t, "`pilco tasks` lists")),
    ("docs/guide.md", "the examples table", lambda t: _table(t, "| script | what it runs")),
    ("docs/guide.md", "the `pilco run TASK` sentence",
     lambda t: _paragraph(t, "runs a task exactly as")),
    ("docs/sweep.md", "the TASK row", lambda t: _table(t, "| `TASK` |")),
])
def test_every_task_is_listed(doc, where, part):
    text = part(_text(doc))
    missing = [name for name in TASKS
               if f"`{name}`" not in text and f"examples/{name}.py" not in text]
    assert not missing, f"{doc}, {where}: tasks of pilco.tasks.TASKS missing: {missing}"


def test_pip_extras_are_quoted():
    """``pip install -e .[sweep]`` fails in zsh, which expands the brackets."""
    problems = [f"{doc}:{n}: {line.strip()}" for doc in DOCS
                for n, line in enumerate(_text(doc).splitlines(), start=1)
                if re.search(r"pip install[^`\n]*\s\.\[", line)]
    assert not problems, "unquoted extras (write \".[extra]\"):\n" + "\n".join(problems)


# -- the README's figures -----------------------------------------------------------------
def _build():
    import importlib.util

    spec = importlib.util.spec_from_file_location("results_build", ROOT / "results" / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_readme_table_is_rendered_from_results():
    build = _build()
    text = _text("README.md")
    start, end = build.readme_block(text)
    assert text[start:end] == build.render_table(build.load_table(), build.load_exports()), \
        "README.md's success table is not what results/ gives: python results/build.py render"


def _figures(text: str) -> Dict[str, Set[str]]:
    """The success counts (``19/20``) and time ratios (``0.81x``) written in ``text``."""
    plain = text.replace("*", "")
    return {"counts": set(re.findall(r"\b\d+/\d+\b", plain)),
            "ratios": set(re.findall(r"\b\d+\.\d+x\b", plain))}


def test_the_readme_performance_xla_figures_are_the_tables_xla_row():
    build = _build()
    rows = build.load_table()
    xla = [row for row in rows if "xla" in build.data_name(row)]
    assert len(xla) == 1, "results/table.json: one row of the XLA sweep"
    row = xla[0]
    cells = " ".join(build.table_row(row, build.load_exports()))
    text = _text("README.md")
    performance = text[text.index("## Performance"):text.index("\n## ", text.index(
        "## Performance") + 1)]
    bullet = next(b for b in performance.split("\n- ") if "--policy-compiler xla" in b)
    # the sentences with a success count: a sweep's (the others give per-evaluation
    # speed-ups, which the table does not hold)
    sweeps = [s for s in re.split(r"(?<=\.)\s+(?=[A-Z])", " ".join(bullet.split()))
              if re.search(r"\b\d+/\d+\b", s)]
    said, given = _figures(" ".join(sweeps)), _figures(cells)
    assert said["counts"] and said["ratios"], bullet
    for kind in ("counts", "ratios"):
        assert said[kind] <= given[kind], (
            f"README.md's Performance section says {sorted(said[kind] - given[kind])} of "
            f"XLA, the table's XLA row (results/table.json) {sorted(given[kind])}")
