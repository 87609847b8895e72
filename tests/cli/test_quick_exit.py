"""The command line's exit skips the interpreter's teardown, and loses nothing on the way out."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

SCRIPT = textwrap.dedent('''
    import atexit, sys, threading, time
    from pathlib import Path
    from sweep3d.cli.quick_exit import exit_now

    folder = Path(sys.argv[1])
    atexit.register(lambda: (folder / "atexit").write_text("ran"))

    def late():
        time.sleep(0.2)
        (folder / "thread").write_text("done")

    threading.Thread(target=late).start()  # not a daemon: the exit waits for it
    sys.stdout.write("no newline, still buffered")
    exit_now(eval(sys.argv[2]))
''')


@pytest.mark.parametrize(("code", "status", "said"), [("0", 0, ""), ("None", 0, ""), ("3", 3, ""),
                                                       ("'what went wrong'", 1, "what went wrong")])
def test_exit_now_runs_exit_handlers_waits_for_threads_and_flushes_output(tmp_path: Path, code: str, status: int,
                                                                          said: str) -> None:
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path), code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == status, done.stderr
    assert done.stdout == "no newline, still buffered"
    assert done.stderr.strip() == said
    assert (tmp_path / "atexit").read_text() == "ran"
    assert (tmp_path / "thread").read_text() == "done"


def test_the_command_keeps_its_exit_status_and_its_one_line_error(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "sweep3d", "plan", str(tmp_path / "missing.toml")],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "missing.toml" in done.stderr + done.stdout and "Traceback" not in done.stderr
