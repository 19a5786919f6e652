"""Command line: `jaxdeploy COMMAND ...`; each command lives in `jaxdeploy/commands/`."""

from __future__ import annotations

import argparse
import atexit
import os
import signal
import sys
import threading

from . import _program_cache
from ._compilation_cache import enable_compilation_cache, prefer_cacheable_errors

prefer_cacheable_errors()  # before any command module imports equinox

from .commands import EXIT_INTERRUPTED, discover  # noqa: E402


def main(argv=None) -> int:
    """Run the command of `argv` (default: the process's own command line) and return its
    exit code. Called without `argv`, as the `jaxdeploy` program is, it ends the process
    itself once the command has returned (`_leave`)."""
    code = _command(argv)
    if argv is None:
        _leave(code)
    return code


def _command(argv) -> int:
    parser = argparse.ArgumentParser(prog="jaxdeploy", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    runners = {}
    for module in discover():
        module.add_arguments(sub.add_parser(module.NAME, help=module.HELP))
        runners[module.NAME] = module.run
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:
        # argparse has printed the usage error (exit code 2) or the help (0); return the code
        # so that callers of `main` (tests, scripts) see it like any other refusal.
        return exit_.code
    # The program cache serves this command only: a script or test that calls `main` and
    # then simulates itself must not read programs from the command's store (its key is the
    # calls' inputs and the package's code, not settings a caller changed in between).
    # JAX's compilation cache may stay on: its key is the compiled program itself.
    programs = _program_cache.folder()
    enable_compilation_cache()
    if argv is None:
        signal.signal(signal.SIGINT, _interrupted(args.command))
    try:
        return runners[args.command](args)
    except KeyboardInterrupt:
        # (Called with `argv`, as tests and scripts do: the exception unwinds, and the output
        # folder's `with` block removes what the run had not finished.)
        print(_interrupt_line(args.command), file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        _program_cache.enable(programs)


def _leave(code) -> None:
    """End the process with exit `code` once its command has returned: what an orderly exit
    does first is done here too (the threads' own exit hooks and a join of every non-daemon
    thread, as `threading._shutdown` does at exit; then the `atexit` handlers: the read-ahead
    hint, logging's flush; then the standard streams), but not the interpreter's teardown of
    every module and of XLA's client, which took 0.15–0.3 s of each command's wall time on
    the 2-core machine (`python -c "import jax; jax.numpy.zeros(3)"`: 0.45 s to its last line,
    0.63 s as a whole process; the command's files are closed long before). Where this
    Python has no `threading._shutdown` (a private function), or `code` is not a number, the
    interpreter exits as usual."""
    shutdown = getattr(threading, "_shutdown", None)
    if shutdown is None or not isinstance(code, int):
        return
    shutdown()
    atexit._run_exitfuncs()
    _flush_if_free(sys.stdout)
    _flush_if_free(sys.stderr)
    os._exit(code)


def _interrupt_line(command: str) -> str:
    return f"interrupted: jaxdeploy {command} stopped (Ctrl-C)"


def _flush_if_free(stream) -> None:
    """Flush `stream` unless the interrupted main thread holds it (or it is closed): what it
    was writing may then be lost, the interrupt line is not."""
    try:
        stream.flush()
    except (RuntimeError, ValueError, OSError):
        pass


def _interrupted(command: str):
    """The program's SIGINT handler: one line, the output folders closed (an unfinished
    result's staging folder removed, the lock released; a sweep's finished chunks are already
    on disk, each written atomically), exit 130 at once. Not a `KeyboardInterrupt`: raised
    inside a callback (JAX's garbage-collection hook) it is swallowed and the command runs
    on; and the interpreter's shutdown can crash while XLA's threads still compile. Python
    runs the handler once the main thread is back from native code (after a compile)."""

    def handler(signum, frame):
        from ._output_folder import close_all

        # The handler runs between two bytecodes of the main thread, which may be inside a
        # write to sys.stderr or sys.stdout (a phase line, a progress bar): writing or
        # flushing that stream again raises "reentrant call inside <_io.BufferedWriter>" and
        # the command ends with a traceback and exit 1 (seen in CI). So the line goes to the
        # file descriptor itself, and the streams' own flushes may fail.
        _flush_if_free(sys.stderr)
        os.write(2, (_interrupt_line(command) + "\n").encode())
        close_all()
        _flush_if_free(sys.stdout)
        os._exit(EXIT_INTERRUPTED)

    return handler


if __name__ == "__main__":
    sys.exit(main())
