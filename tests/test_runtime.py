"""pilco.runtime: TensorFlow's quiet start-up, logging and thread set-up of the commands.

The start-up tests run in processes of their own: each imports TensorFlow at most once,
and what it writes to file descriptor 2 is what is checked. A stand-in ``tensorflow``
package (on ``PYTHONPATH`` before the installed one) writes the probe lines of a machine
without CUDA at import, so the filter is checked line by line; one test imports the real
TensorFlow.
"""
from __future__ import annotations

import logging
import os
import subprocess
import sys
import textwrap

import pytest

from pilco import runtime

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

ABSL_NOTE = ("WARNING: All log messages before absl::InitializeLog() is called are written "
             "to STDERR")
NO_DRIVERS = ("I0000 00:00:1700000000.000000    1234 cudart_stub.cc:31] Could not find cuda "
              "drivers on your machine, GPU will not be used.")
CUINIT = ("E0000 00:00:1700000000.000000    1234 cuda_platform.cc:52] failed call to cuInit: "
          "INTERNAL: CUDA error: Failed call to cuInit: UNKNOWN ERROR (303)")
FACTORY = ("E0000 00:00:1700000000.000000    1234 cuda_dnn.cc:8310] Unable to register cuDNN "
           "factory: Attempting to register factory for plugin cuDNN when one has already "
           "been registered")


def fake_tensorflow(tmp_path, body: str) -> str:
    """A directory holding a stand-in ``tensorflow`` package whose import runs ``body``
    (``os`` and ``sys`` imported); returns the directory."""
    package = tmp_path / "fake" / "tensorflow"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("import os, sys\n" + textwrap.dedent(body))
    return str(package.parent)


def run_python(code: str, *paths: str, env_extra=None, unset=("TF_CPP_MIN_LOG_LEVEL",)):
    """Run ``code`` in a new interpreter with ``paths`` and the repository first on its
    path; returns the finished process (text output)."""
    env = {k: v for k, v in os.environ.items() if k not in unset}
    env["PYTHONPATH"] = os.pathsep.join([*paths, ROOT, *filter(None, [env.get("PYTHONPATH")])])
    env.update(env_extra or {})
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


PROBE = f"""
os.write(2, b"{ABSL_NOTE}\\n{NO_DRIVERS}\\n")
os.write(2, b"kept: a line of the import\\n")
print("kept: Python's stderr during the import", file=sys.stderr, flush=True)
os.write(2, b"{ABSL_NOTE}\\n{NO_DRIVERS}\\n{FACTORY}\\n")

class config:
    @staticmethod
    def list_physical_devices(kind):  # TensorFlow probes CUDA when it lists devices
        os.write(2, b"{CUINIT}\\n")
        return []
"""


def test_the_probe_lines_go_and_every_other_line_stays(tmp_path):
    fake = fake_tensorflow(tmp_path, PROBE)
    done = run_python("""
        import os, sys
        from pilco.runtime import quiet_tensorflow
        os.write(2, b"before\\n")
        quiet_tensorflow()
        import tensorflow
        os.write(2, b"after\\n")
        print(os.environ["TF_CPP_MIN_LOG_LEVEL"])
        """, fake)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "2\n"  # the default level, set for processes started from here
    assert done.stderr.splitlines() == [
        "before", "kept: a line of the import", "kept: Python's stderr during the import",
        "after"]


def test_an_import_that_fails_keeps_its_output_and_restores_stderr(tmp_path):
    fake = fake_tensorflow(tmp_path, f"""
        os.write(2, b"{NO_DRIVERS}\\nkept: before the failure\\n")
        raise ImportError("the import failed here")
        """)
    done = run_python("""
        import os
        from pilco.runtime import quiet_tensorflow
        quiet_tensorflow()
        try:
            import tensorflow
        except ImportError as err:
            os.write(2, f"caught: {err}\\n".encode())
        import tensorflow  # the second import is not filtered: its traceback is shown
        """, fake)
    assert done.returncode == 1
    lines = done.stderr.splitlines()
    assert lines[:2] == ["kept: before the failure", "caught: the import failed here"]
    assert "Could not find cuda drivers" in done.stderr  # the unfiltered second import
    assert lines[-1] == "ImportError: the import failed here"


def test_a_machine_with_drivers_keeps_its_cuinit_failure(tmp_path):
    """The cuInit failure is a probe line only beside the no-drivers line."""
    fake = fake_tensorflow(tmp_path, f"""
        class config:
            @staticmethod
            def list_physical_devices(kind):
                os.write(2, b"{CUINIT}\\n")
        """)
    done = run_python("from pilco.runtime import quiet_tensorflow; quiet_tensorflow(); "
                      "import tensorflow", fake)
    assert done.returncode == 0 and done.stderr.splitlines() == [CUINIT]


@pytest.mark.parametrize("setting, filtered", [("0", False), ("3", True)])
def test_the_level_set_by_the_user_is_kept_and_level_0_shows_everything(
        tmp_path, setting, filtered):
    fake = fake_tensorflow(tmp_path, PROBE)
    done = run_python("""
        import os
        from pilco.runtime import quiet_tensorflow
        quiet_tensorflow()
        import tensorflow
        print(os.environ["TF_CPP_MIN_LOG_LEVEL"])
        """, fake, env_extra={"TF_CPP_MIN_LOG_LEVEL": setting})
    assert done.returncode == 0 and done.stdout == f"{setting}\n"
    assert ("Could not find cuda drivers" in done.stderr) is not filtered
    assert "kept: a line of the import" in done.stderr


def test_nothing_happens_once_tensorflow_is_imported_or_the_second_time(tmp_path):
    fake = fake_tensorflow(tmp_path, "")
    done = run_python("""
        import os, sys
        from pilco import runtime
        runtime.quiet_tensorflow()
        runtime.quiet_tensorflow()
        print(sum(isinstance(f, runtime._TensorFlowImportFilter) for f in sys.meta_path))
        import tensorflow
        sys.meta_path[:] = [f for f in sys.meta_path
                            if not isinstance(f, runtime._TensorFlowImportFilter)]
        del os.environ["TF_CPP_MIN_LOG_LEVEL"]
        runtime.quiet_tensorflow()  # TensorFlow is imported: no filter, no variable
        print(len([f for f in sys.meta_path if isinstance(f, runtime._TensorFlowImportFilter)]),
              "TF_CPP_MIN_LOG_LEVEL" in os.environ)
        """, fake)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["1", "0 False"]


def test_the_real_tensorflow_starts_without_its_cuda_probe_lines():
    """The installed TensorFlow, imported after :func:`quiet_tensorflow`: no CUDA probe
    line, a line written to fd 2 in the middle of the import (when ``tensorflow.python``
    is looked up) is kept, and the thread pools can still be sized afterwards."""
    done = run_python("""
        import os, sys
        from pilco.runtime import configure_threads, quiet_tensorflow

        class Marker:
            def find_spec(self, name, path=None, target=None):
                if name == "tensorflow.python":
                    os.write(2, b"deliberate: written during the import\\n")
                return None

        quiet_tensorflow()
        sys.meta_path.insert(0, Marker())
        import tensorflow as tf
        configure_threads(2)
        tf.constant(1.0) + 1.0
        print(tf.config.threading.get_intra_op_parallelism_threads(),
              tf.config.threading.get_inter_op_parallelism_threads())
        """)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split() == ["2", "2"]
    assert "deliberate: written during the import" in done.stderr
    for probe in ("Could not find cuda drivers", "cuInit", "Unable to register cu",
                  "absl::InitializeLog"):
        assert probe not in done.stderr, done.stderr


def test_probe_lines_are_matched_narrowly():
    lines = [ABSL_NOTE.encode() + b"\n", b"cuda drivers are fine\n", NO_DRIVERS.encode(),
             ABSL_NOTE.encode() + b"\n", b"Unable to register the plugin\n"]
    assert runtime._probe_lines(lines) == [False, False, True, False, False]


ONEDNN = ("I0000 00:00:1700000000.000000    1234 port.cc:153] oneDNN custom operations are "
          "on. You may see slightly different numerical results due to floating-point "
          "round-off errors from different computation orders.")
WARNED = ("W0000 00:00:1700000000.000000    1234 gpu_device.cc:2344] Cannot dlopen some GPU "
          "libraries.")


def test_lines_below_the_users_level_go_with_their_absl_note():
    """Lines in absl's format that TensorFlow writes before it reads TF_CPP_MIN_LOG_LEVEL
    go when their severity is below the level; lines of other formats always stay."""
    lines = [ABSL_NOTE.encode() + b"\n", ONEDNN.encode() + b"\n", WARNED.encode() + b"\n",
             CUINIT.encode() + b"\n", b"I0000 is not a log line\n"]
    assert runtime._probe_lines(lines, 0) == [False] * 5
    assert runtime._probe_lines(lines, 1) == [True, True, False, False, False]
    assert runtime._probe_lines(lines, 2) == [True, True, True, False, False]
    assert runtime._probe_lines(lines, 3) == [True, True, True, True, False]


# ----------------------------------------------------------------------------- logging
def test_log_levels_by_name_in_any_case():
    assert runtime.log_level("warning") == logging.WARNING
    assert runtime.log_level(" Info ") == logging.INFO
    assert runtime.log_level("DEBUG") == logging.DEBUG
    assert runtime.log_level(15) == 15
    for bad in ("loud", "", "BASIC_FORMAT", None, True):
        with pytest.raises(ValueError, match=f"unknown logging level {bad!r}; choose one "
                                             f"of DEBUG, INFO, WARNING, ERROR, CRITICAL"):
            runtime.log_level(bad)


def test_configure_logging_sets_the_root_or_one_logger():
    done = run_python("""
        import logging
        from pilco.runtime import configure_logging
        configure_logging("debug")
        root = logging.getLogger()
        print(root.level, root.handlers[0].formatter._fmt)
        """)
    assert done.stdout == "10 %(asctime)s %(name)s %(levelname)s: %(message)s\n"
    done = run_python("""
        import logging
        from pilco.runtime import configure_logging
        configure_logging("info", logger="pilco")
        print(logging.getLogger().level, logging.getLogger("pilco").level)
        configure_logging("nope")
        """)
    assert done.stdout == "30 20\n"
    assert "ValueError: unknown logging level 'nope'" in done.stderr


# ----------------------------------------------------------------------------- threads
def test_configure_threads_sets_one_intra_op_thread_unless_told(monkeypatch):
    # the arithmetic switch is process-wide: recorded here, checked in its own process below
    calls = []
    monkeypatch.setattr(runtime, "reproducible_arithmetic", lambda: calls.append(1))
    monkeypatch.delenv("TF_NUM_INTRAOP_THREADS", raising=False)
    runtime.configure_threads()
    assert calls == [1]
    assert os.environ["TF_NUM_INTRAOP_THREADS"] == "1"
    monkeypatch.setenv("TF_NUM_INTRAOP_THREADS", "4")
    runtime.configure_threads()
    assert os.environ["TF_NUM_INTRAOP_THREADS"] == "4"
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="threads"):
            runtime.configure_threads(bad)


def test_configure_threads_turns_off_the_arithmetic_optimizer_for_every_function():
    done = run_python("""
        import tensorflow as tf
        before = tf.config.optimizer.get_experimental_options().get("arithmetic_optimization")
        from pilco.runtime import configure_threads
        configure_threads()
        after = tf.config.optimizer.get_experimental_options()["arithmetic_optimization"]
        print(before, after)
        """)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split() == ["None", "False"]
    kept = run_python("""
        import tensorflow as tf
        from pilco.runtime import configure_threads
        configure_threads()
        print(tf.config.optimizer.get_experimental_options().get("arithmetic_optimization"))
        """, env_extra={runtime.ARITHMETIC_OPTIMIZER_VARIABLE: "1"})
    assert kept.returncode == 0, kept.stderr[-3000:]
    assert kept.stdout.split() == ["None"]


def test_configure_threads_leaves_the_blas_libraries_one_thread(monkeypatch):
    monkeypatch.setattr(runtime, "reproducible_arithmetic", lambda: None)
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import numpy  # noqa: F401 - loads its BLAS

    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        runtime.configure_threads()
        blas = [i for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
        assert blas and all(i["num_threads"] == 1 for i in blas)


def test_thread_environment():
    env = runtime.thread_environment(3, {"PATH": "/bin", "OMP_NUM_THREADS": "8"})
    assert env["PATH"] == "/bin"
    for name in runtime.THREAD_VARIABLES:  # TensorFlow's ops one thread each, 3 side by side
        assert env[name] == ("1" if name == "TF_NUM_INTRAOP_THREADS" else "3")
    assert env["TF_CPP_MIN_LOG_LEVEL"] == runtime.TF_LOG_LEVEL
    assert runtime.thread_environment(1, {"TF_CPP_MIN_LOG_LEVEL": "3"})[
        "TF_CPP_MIN_LOG_LEVEL"] == "3"
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="threads"):
            runtime.thread_environment(bad)
