"""The main job (``scripts/demo``), end to end as a newcomer runs it: every node a real process
over DDS, the summary's targets met, its plots written and its bag readable."""

import os
import pathlib
import subprocess
import sys

import pytest

from inflarm_hw.bag import bag_info

pytestmark = pytest.mark.system
REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
PLOTS = ('soft_arm_path.png', 'soft_arm_clearance.png', 'inflatable_arm_tip.png',
         'inflatable_arm_motors.png')
TARGET_ROWS = (  # (arm, quantity) of the rows the acceptance names
    ('soft arm', 'tracking error, max (true end to the planned path)'),
    ('soft arm', 'contact with the obstacle'),
    ('inflatable arm', 'load error'),
    ('inflatable arm', 'true tip off the path, max'),
)


def summary_rows(text: str) -> dict[tuple[str, str], list[str]]:
    rows = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        if len(cells) == 5 and cells[0] in ('soft arm', 'inflatable arm'):
            rows[(cells[0], cells[1])] = cells[2:]
    return rows


def test_the_main_job_meets_its_targets_and_writes_its_outputs(domain_id, tmp_path):
    out = tmp_path / 'demo'
    run = subprocess.run(
        [sys.executable, '-m', 'inflarm_bringup.demo', '--out', str(out)],
        env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)), cwd=REPO_ROOT,
        capture_output=True, text=True, timeout=240)
    log = run.stdout[-4000:] + run.stderr[-4000:]
    assert run.returncode == 0, log
    assert '[demo] ' in run.stdout and 'soft arm: following the path' in run.stdout  # progress

    rows = summary_rows((out / 'summary.md').read_text())
    for key in TARGET_ROWS:
        assert rows[key][2] == 'yes', f'{key}: {rows[key]}\n{log}'
    error_mm = float(rows[('soft arm', 'tracking error, max (true end to the planned path)')][0]
                     .removesuffix(' mm'))
    # The paper's figure, a user's target, not widened for load: 3.19 mm measured with three CPU
    # hogs beside the test (load average 15 on the 2 cores).
    assert 0.0 < error_mm < 5.0  # measured, not a placeholder
    for plot in PLOTS:
        assert (out / plot).stat().st_size > 10_000, plot

    info = bag_info(out / 'bag')
    counts = {name.lstrip('/'): topic.message_count
              for name, topic in info.topics.items()}
    for topic in ('ball_position', 'planned_path', 'chamber_pressure_command', 'joint_states',
                  'estimated_wrench', 'tip_trajectory', 'motor_position_command'):
        assert counts.get(topic, 0) > 0, (topic, counts)
