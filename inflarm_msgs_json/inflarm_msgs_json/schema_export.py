"""Write the JSON Schema of every message type to ``<dir>/<Type>.schema.json``.

Usage: ``python -m inflarm_msgs_json.schema_export <dir>`` (the package's ``schema/`` directory
holds the checked-in copies, which a test keeps equal to the generated ones).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import inflarm_msgs_json  # noqa: F401  (defines and so registers the message types)
from inflarm_msgs_json.spec import MESSAGE_TYPES, Message, json_schema


def schema_filename(cls: type[Message]) -> str:
    """Return the schema file name of a message class, e.g. ``'ObstacleSet.schema.json'``."""
    return f'{cls.type}.schema.json'


def schema_text(cls: type[Message]) -> str:
    """Return the schema of a message class as the exact text written to its file."""
    return json.dumps(json_schema(cls), indent=2) + '\n'


def export(directory: str | Path) -> list[Path]:
    """Write one schema file per message type into ``directory`` (created if missing).

    Parameters
    ----------
    directory : str or Path
        Target directory.

    Returns
    -------
    list of Path
        The files written, sorted by type name.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for name in sorted(MESSAGE_TYPES):
        cls = MESSAGE_TYPES[name]
        path = directory / schema_filename(cls)
        path.write_text(schema_text(cls), encoding='utf-8')
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('directory', type=Path, help='where to write <Type>.schema.json')
    args = parser.parse_args(argv)
    for path in export(args.directory):
        print(path)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
