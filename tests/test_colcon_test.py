"""`colcon test` runs the suite: the suite is the package inflarm_tests (tests/package.xml), and
colcon's pytest step runs it and writes the JUnit XML that `colcon test-result` counts.

The package is built and tested in a temporary build and install base (the workspace's install/
is left alone; the packages under test come from it, as from an underlay), on one light part of
the suite, the message codec's tests, so that this takes seconds.
"""

import os
import pathlib
import re
import subprocess
import sys

import pytest

pytestmark = pytest.mark.system
REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
COLCON = pathlib.Path(sys.executable).with_name('colcon')  # the venv's, beside its python
LIGHT_PART = 'msgs_json/test_msgs_json_messages.py'  # relative to tests/, where colcon runs pytest
SUMMARY = re.compile(r'Summary: (\d+) tests, (\d+) errors, (\d+) failures, (\d+) skipped')


def run(*command: str) -> subprocess.CompletedProcess:
    # Without the options colcon gives this run of pytest when the suite runs under colcon test.
    env = {k: v for k, v in os.environ.items() if k != 'PYTEST_ADDOPTS'}
    done = subprocess.run(command, cwd=REPO_ROOT, env=env, capture_output=True, text=True,
                          timeout=240)
    assert done.returncode == 0, f'{command}:\n{done.stdout}\n{done.stderr}'
    return done


def test_colcon_test_runs_the_suite_and_test_result_counts_its_tests(tmp_path):
    bases = ['--base-paths', str(REPO_ROOT), '--build-base', str(tmp_path / 'build'),
             '--install-base', str(tmp_path / 'install')]
    run(str(COLCON), '--log-base', str(tmp_path / 'log'), 'build',
        '--packages-select', 'inflarm_tests', *bases)
    run(str(COLCON), '--log-base', str(tmp_path / 'log'), 'test',
        '--packages-select', 'inflarm_tests', *bases, '--pytest-args', LIGHT_PART)

    junit = tmp_path / 'build' / 'inflarm_tests' / 'pytest.xml'
    assert 'classname="inflarm_tests.tests.msgs_json.test_msgs_json_messages"' in junit.read_text()
    result = run(str(COLCON), '--log-base', str(tmp_path / 'log'), 'test-result',
                 '--test-result-base', str(tmp_path / 'build'))
    summary = SUMMARY.search(result.stdout)
    assert summary, result.stdout
    tests, errors, failures, _ = map(int, summary.groups())
    collected = run(sys.executable, '-m', 'pytest', '--collect-only', '-q',
                    '-p', 'no:cacheprovider', f'tests/{LIGHT_PART}').stdout
    expected = int(re.search(r'^(\d+) tests? collected', collected, re.MULTILINE).group(1))
    assert (tests, errors, failures) == (expected, 0, 0), result.stdout
    assert tests > 0
