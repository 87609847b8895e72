"""Leaving the process without tearing the interpreter down.

Once torch is loaded (a near tie's check, a torch model), Python's own shutdown frees its
thousands of modules one by one: about half a second on two cores after every other line is
printed (benchmarks/RESULTS.md, issue 46). The command line does not need it: what a command
wrote is closed by then, and what still must happen at exit (exit handlers: multiprocessing's,
temporary folders', Ray's; threads that are not daemons; buffered output) happens here first.
"""

from __future__ import annotations

import atexit
import os
import sys
import threading
from typing import NoReturn


def exit_now(code: object = 0) -> NoReturn:
    """End the process with ``code`` as ``SystemExit`` reads it (None: 0; an int; anything else
    printed to stderr, 1), after the threads that are not daemons end, the exit handlers run and
    the standard streams are flushed."""
    for thread in threading.enumerate():
        if thread is not threading.current_thread() and not thread.daemon:
            thread.join()
    atexit._run_exitfuncs()  # they do not run again: os._exit skips them
    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:
        _write(sys.stderr, f"{code}\n")
        status = 1
    for stream in (sys.stdout, sys.stderr):
        _flush(stream)
    os._exit(status)


def _write(stream, text: str) -> None:
    try:
        stream.write(text)
    except (OSError, ValueError):  # a closed or broken stream: nothing more can be said
        pass


def _flush(stream) -> None:
    try:
        stream.flush()
    except (OSError, ValueError):  # the reader went away (``query … | head``) or the stream is closed
        pass
