"""``inflarm-characterize``: Table 3 and Fig 9 of 000_ce37cf035a0a87c6 from cantilever samples.

Usage::

    inflarm-characterize samples.csv --out DIR
    inflarm-characterize samples.csv --out DIR --synthetic [--seed N]

Reads the samples CSV (header ``pressure_pa,displacement_m,force_n,probe_distance_m,
spring_offset_m``) and writes ``DIR/table3.csv``, ``DIR/table3.md`` and ``DIR/fig9.png``. With
``--synthetic`` it first writes seeded synthetic samples consistent with the paper's Table 3 to
``samples.csv`` (which must not exist yet), then processes them, so the tool can be tried without
a test rig. Exit status: 0 on success, 1 on a bad or unreadable input file, 2 on bad arguments.
"""

import argparse
from collections.abc import Sequence
import os
import sys

import numpy as np

from inflarm_model.characterization import (
    DEFAULT_PRESSURE_STEP,
    SAMPLES_HEADER,
    characterize,
    plot_characteristic,
    read_samples_csv,
    synthetic_samples,
    table3_csv,
    table3_markdown,
    write_samples_csv,
)
from inflarm_model.link import LINK_RADIUS
from inflarm_msgs_json.cli import positive_float, run_command

PROG = 'inflarm-characterize'
DEFAULT_SEED = 7


def build_parser() -> argparse.ArgumentParser:
    """Command-line parser of ``inflarm-characterize``."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description='Fit the inflatable-link stiffness k and saturation torque M_max per '
                    'pressure from cantilever samples (Table 3 and Fig 9 of the paper).',
    )
    parser.add_argument('samples', help='samples CSV with the header ' + ','.join(SAMPLES_HEADER)
                        + ' (SI units); with --synthetic, the file to create')
    parser.add_argument('--out', required=True, metavar='DIR',
                        help='output directory for table3.csv, table3.md, fig9.png '
                             '(created if missing)')
    parser.add_argument('--synthetic', action='store_true',
                        help='write synthetic samples consistent with Table 3 to SAMPLES first')
    parser.add_argument('--seed', type=int, default=None,
                        help=f'seed of the synthetic samples (default: {DEFAULT_SEED})')
    parser.add_argument('--radius', type=positive_float, default=LINK_RADIUS,
                        help='link radius r [m] for the wrinkling moment (default: %(default)s)')
    parser.add_argument('--pressure-step', type=positive_float, default=DEFAULT_PRESSURE_STEP,
                        help='resolution used to group samples by pressure [Pa] '
                             '(default: %(default)s)')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; returns the exit status (0 ok, 1 bad input file, 2 bad arguments)."""
    return run_command(build_parser(), argv, _characterize, errors=(OSError, ValueError),
                       error_status=1)


def _characterize(args: argparse.Namespace) -> int:
    if args.seed is not None and not args.synthetic:
        raise argparse.ArgumentError(None, '--seed needs --synthetic')
    if args.synthetic:
        if os.path.exists(args.samples):
            raise FileExistsError(f'{args.samples} exists; --synthetic will not overwrite it')
        seed = DEFAULT_SEED if args.seed is None else args.seed
        write_samples_csv(args.samples, synthetic_samples(np.random.default_rng(seed)))
    samples = read_samples_csv(args.samples)
    fits = characterize(samples, radius=args.radius, pressure_step=args.pressure_step)
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, 'table3.csv'), 'w', encoding='utf-8') as handle:
        handle.write(table3_csv(fits))
    with open(os.path.join(args.out, 'table3.md'), 'w', encoding='utf-8') as handle:
        handle.write(table3_markdown(fits))
    plot_characteristic(samples, fits, os.path.join(args.out, 'fig9.png'),
                        pressure_step=args.pressure_step)
    print(table3_markdown(fits), end='')
    print(f'wrote {", ".join(os.path.join(args.out, n) for n in _OUTPUTS)}')
    return 0


_OUTPUTS = ('table3.csv', 'table3.md', 'fig9.png')


if __name__ == '__main__':
    sys.exit(main())
