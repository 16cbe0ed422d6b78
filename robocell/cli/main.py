"""The ``robocell`` command: one entry point for every part of robocell.

Each command lives in a module of this package that registers it (see
``robocell.cli.command``); :data:`MODULES` lists them in the order ``--help``
shows them.
"""

from __future__ import annotations

import os

# The fit's 11-parameter L-BFGS-B gains nothing from BLAS threads, and loses a lot to them on a
# busy machine (measured: 4 ms alone, 15-97 ms beside another process). This must precede numpy.
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse
import logging
import signal
import sys

from robocell.core_cy.errors import CoreError
from robocell.wire.errors import CellError

from . import calibrate, camera, config, demo, export, jobs, reconstruct, replay, services, sim
from .command import Commands

__all__ = ["build_parser", "main", "MODULES"]

MODULES = (reconstruct, sim, services, jobs, export, replay, config, calibrate, camera, demo)
#: The exit status of a program whose reader went away (128 + SIGPIPE), as a shell reports it.
_BROKEN_PIPE_STATUS = 141
#: Libraries whose INFO messages are left out unless -v.
_QUIET_LIBRARIES = ("httpx", "httpcore", "PIL", "trimesh", "rosbags")
#: After Ctrl-C, as a shell reports a program it stopped with SIGINT.
_INTERRUPTED_STATUS = 130


def _global_options(parser: argparse.ArgumentParser, *, default) -> None:
    parser.add_argument("-v", "--verbose", action="store_true", default=default, help="log debug messages")
    parser.add_argument("--config", metavar="FILE", default=default,
                        help="cell configuration, TOML (default: built-in); before or after the command")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robocell", description="Graspable superquadric models of unknown objects, from a robot cell.")
    _global_options(parser, default=None)
    parser.set_defaults(verbose=False)
    # After the command, a global option given there wins; left out, it keeps what was given before it.
    after = argparse.ArgumentParser(add_help=False)
    _global_options(after, default=argparse.SUPPRESS)
    commands = Commands(parser.add_subparsers(dest="_command", required=True, metavar="COMMAND"), "", [after])
    for module in MODULES:
        module.register(commands)
    return parser


def _stdout_gone() -> int:
    # The reader (`robocell jobs | head`) stopped reading: say nothing, and keep Python from
    # complaining again when it flushes stdout on the way out.
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return _BROKEN_PIPE_STATUS


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    if not args.verbose:
        # Libraries' own progress (httpx logs every request at INFO) is noise to a user; -v shows it.
        for library in _QUIET_LIBRARIES:
            logging.getLogger(library).setLevel(logging.WARNING)
    try:
        status = args.run(args)
        if status == _INTERRUPTED_STATUS:
            # The command heard Ctrl-C and handled it: one more while it exits has nothing left to stop.
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        sys.stdout.flush()  # here, where a closed pipe can still be handled
        return status
    except BrokenPipeError:
        return _stdout_gone()
    except KeyboardInterrupt:  # Ctrl-C: the user knows why it stopped
        return _INTERRUPTED_STATUS
    except (CellError, CoreError, OSError) as exc:  # OSError: a file or directory that cannot be read or made
        print(f"robocell {args.command}: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:  # option values the parser could not check
        print(f"robocell {args.command}: {_one_line(exc)}", file=sys.stderr)
        return 2


def _one_line(exc: ValueError) -> str:
    from pydantic import ValidationError  # loaded already, if it raised this

    from robocell.wire.messages import field_errors

    return field_errors(exc) if isinstance(exc, ValidationError) else " ".join(str(exc).split())


if __name__ == "__main__":
    sys.exit(main())
