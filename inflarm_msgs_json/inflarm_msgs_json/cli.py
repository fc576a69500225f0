"""What the command-line tools share: argparse ``type=`` callables and the run of a ``main``.

Each type raises ``argparse.ArgumentTypeError`` naming what was wrong, which argparse turns into
a usage error (exit 2) naming the option. `run_command` parses the arguments, runs the tool and
turns argparse's exits, usage errors and the tool's errors into exit statuses.
"""

import argparse
from collections.abc import Callable, Sequence
import math
import sys

__all__ = ['positive_float', 'run_command']


def positive_float(text: str) -> float:
    """A finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f'expected a positive finite number, got {text!r}')
    return value


def run_command(parser: argparse.ArgumentParser, argv: Sequence[str] | None,
                command: Callable[[argparse.Namespace], int], *,
                errors: tuple[type[Exception], ...] = (), error_status: int = 1) -> int:
    """Parse ``argv`` with ``parser`` and run ``command`` on the result; return an exit status.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The tool's parser; its ``prog`` starts the error lines.
    argv : sequence of str or None
        The arguments (None: ``sys.argv[1:]``).
    command : callable
        Runs the tool on the parsed arguments and returns its exit status. It raises
        ``argparse.ArgumentError(None, reason)`` for a usage error found after parsing (an
        option that needs another, say).
    errors : tuple of exception types, optional
        The tool's errors: each prints ``PROG: error: reason`` to stderr and returns
        ``error_status``. None by default (they propagate).
    error_status : int, optional
        The status of those errors (1 by default).

    Returns
    -------
    int
        argparse's own status on ``--help`` (0) and on a usage error (2), 2 on an
        ``ArgumentError`` from ``command`` (after the usage, as argparse prints it),
        ``error_status`` on one of ``errors``, else what ``command`` returns.
    """
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse exits on --help and usage errors
        return int(exc.code) if isinstance(exc.code, int) else 2
    try:
        return command(args)
    except argparse.ArgumentError as exc:
        parser.print_usage(sys.stderr)
        print(f'{parser.prog}: error: {exc}', file=sys.stderr)
        return 2
    except errors as exc:
        print(f'{parser.prog}: error: {exc}', file=sys.stderr)
        return error_status
