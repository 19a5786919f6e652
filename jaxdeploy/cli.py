"""Command line: `jaxdeploy COMMAND ...`; each command lives in `jaxdeploy/commands/`."""

from __future__ import annotations

import argparse
import sys

from ._compilation_cache import enable_compilation_cache, prefer_cacheable_errors

prefer_cacheable_errors()  # before any command module imports equinox

from .commands import discover  # noqa: E402


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
    return runners[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
