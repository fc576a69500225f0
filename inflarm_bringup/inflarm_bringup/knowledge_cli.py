"""``inflarm-build-knowledge OUT``: build the experiential knowledge database (3.2 of 001_).

Runs the learning trials against the simulated plant (``inflarm_hw.sra_plant``) for every
knowledge point of the 1 cm grid
(67,200 points; about 1.5 min on two cores) and writes the memory-mapped database (a directory
of .npy files) to OUT, which
the pressure controller's ``knowledge_db_path`` parameter then reads. An interrupted build
resumes where it stopped. With ``--scheduler tcp://HOST:8786`` the blocks of points are learned
by the workers of a Dask distributed cluster instead of local processes (same files, same
bytes);
an unreachable scheduler or a worker of another version exits with status 2 and the reason.

The plant is `knowledge_plant`: the default simulated arm, valve delay included (the memory is
learned on the arm's dynamics as they are), measured exactly: measurement noise would only make
a rebuild differ from the database it rebuilds.
"""

import argparse
import sys

from inflarm_control.knowledge import ClusterError, build_knowledge_database
from inflarm_hw.sra_plant import NOISE_FREE, SoftArmPlant


def knowledge_plant(n: int) -> SoftArmPlant:
    """``n`` simulated arms to learn the database on: the default plant, measured exactly."""
    return SoftArmPlant(n, NOISE_FREE)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='inflarm-build-knowledge',
                                     description=__doc__.splitlines()[0].split(': ', 1)[1])
    parser.add_argument('out', help='database directory to write (or resume)')
    parser.add_argument('--trials', type=int, default=30, help='learning trials per point')
    parser.add_argument('--workers', type=int, default=None,
                        help='local processes (default: one per core; not with --scheduler)')
    parser.add_argument('--scheduler', default=None, metavar='tcp://HOST:8786',
                        help='Dask scheduler whose workers learn the points (default: local)')
    parser.add_argument('--overwrite', action='store_true', help='start over if OUT exists')
    args = parser.parse_args(argv)
    try:
        db = build_knowledge_database(args.out, plant_factory=knowledge_plant,
                                      n_trials=args.trials, workers=args.workers,
                                      scheduler=args.scheduler, overwrite=args.overwrite)
    except ClusterError as err:
        print(f'inflarm-build-knowledge: {err}', file=sys.stderr)
        return 2
    except (OSError, ValueError) as err:
        print(f'inflarm-build-knowledge: {err}', file=sys.stderr)
        return 1
    print(f'{args.out}: {db.n_filled} knowledge points')
    db.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
