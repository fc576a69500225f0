"""The README says what the code does: its first screen gives the two commands CI and a
newcomer run, its topic table is the nodes' own, and it names every node executable."""

import pathlib
import re

from catkin_pkg.package import parse_package
from interface_table import interface_rows

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
README = (REPO_ROOT / 'README.md').read_text()


def test_the_first_screen_gives_the_main_job_and_the_test_command():
    first_screen = '\n'.join(README.splitlines()[:30])
    assert 'scripts/demo' in first_screen and 'scripts/test.sh' in first_screen
    assert 'scripts/test.sh' in (REPO_ROOT / '.ci' / 'run').read_text()


def test_the_topic_table_is_what_the_nodes_use(domain_id, tmp_path):
    missing = [row for row in interface_rows(domain_id, str(tmp_path / 'mcu'))[0]
               if row not in README]
    assert not missing, 'README topic table out of date; python tests/interface_table.py:\n' \
        + '\n'.join(missing)


def test_every_node_executable_is_in_the_node_table():
    for package in REPO_ROOT.glob('inflarm_*/package.xml'):
        name = parse_package(str(package)).name
        setup = (package.parent / 'setup.py').read_text()
        for executable in re.findall(r"'([a-z_]+) = [a-z_.]+executables:", setup):
            assert f'| `{executable}` |' in README, f'{name}/{executable} missing'
