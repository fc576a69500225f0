"""The subset of the ros2 CLI this workspace needs: `run` and `pkg executables`.

`ros2 run <pkg> <exe> [args...]` is `get_package_prefix(pkg)/lib/<pkg>/<exe>`, exec'd with the
remaining arguments (``--ros-args ...`` included), exactly as ros2run does it.
"""

import argparse
import os
import sys

from ament_index_python.packages import (
    PackageNotFoundError,
    get_package_prefix,
    get_packages_with_prefixes,
)


def executables(package: str) -> list[str]:
    """Executable files installed under ``<prefix>/lib/<package>``, sorted."""
    lib_dir = os.path.join(get_package_prefix(package), 'lib', package)
    if not os.path.isdir(lib_dir):
        return []
    return sorted(
        name for name in os.listdir(lib_dir)
        if os.path.isfile(os.path.join(lib_dir, name))
        and os.access(os.path.join(lib_dir, name), os.X_OK)
    )


def run(package: str, executable: str, argv: list[str]) -> None:
    """Replace this process with the package's executable (never returns on success)."""
    path = os.path.join(get_package_prefix(package), 'lib', package, executable)
    if not os.access(path, os.X_OK):
        known = ', '.join(executables(package)) or 'none'
        sys.exit(f"No executable '{executable}' in package '{package}' (it has: {known})")
    os.execv(path, [path, *argv])


def main() -> None:
    parser = argparse.ArgumentParser(prog='ros2', description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest='command', required=True)
    run_parser = commands.add_parser('run', help='run an executable of a package')
    run_parser.add_argument('package')
    run_parser.add_argument('executable')
    run_parser.add_argument('argv', nargs=argparse.REMAINDER)
    pkg_parser = commands.add_parser('pkg', help='package queries')
    pkg_commands = pkg_parser.add_subparsers(dest='pkg_command', required=True)
    exe_parser = pkg_commands.add_parser('executables', help='list executables')
    exe_parser.add_argument('package', nargs='?')
    args = parser.parse_args()

    try:
        if args.command == 'run':
            run(args.package, args.executable, args.argv)
        packages = [args.package] if args.package else sorted(get_packages_with_prefixes())
        for package in packages:
            for name in executables(package):
                print(package, name)
    except PackageNotFoundError:
        sys.exit(f"Package '{args.package}' not found")


if __name__ == '__main__':
    main()
