"""Command line: `jaxdeploy COMMAND ...`; each command lives in `jaxdeploy/commands/`."""

from __future__ import annotations

import argparse
import os
import sys

from ._compilation_cache import enable_compilation_cache, prefer_cacheable_errors

prefer_cacheable_errors()  # before any command module imports equinox

from .commands import discover  # noqa: E402
from .commands._args import EXIT_INTERRUPTED  # noqa: E402


def main(argv=None) -> int:
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
    enable_compilation_cache()
    try:
        return runners[args.command](args)
    except KeyboardInterrupt:
        # One line, not a traceback; what a command finished is already on disk (files are
        # written atomically, a sweep's chunks as they finish) and what it had not is removed
        # on the way out (the staging folder of `jaxdeploy._output_folder`).
        print(f"interrupted: jaxdeploy {args.command} stopped (Ctrl-C)", file=sys.stderr)
        if argv is None:
            # The program itself: end now, without the interpreter's shutdown, which can crash
            # while XLA's threads are still compiling (a segfault instead of exit 130).
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(EXIT_INTERRUPTED)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
