"""inflarm-sra-experiments: Figs 7-8 on the simulated soft arm, written to a folder."""

import pytest

from inflarm_bringup.sra_experiments import main


def test_fig7_fig8_experiment_writes_figures_and_tables(tmp_path):
    assert main(['--out', str(tmp_path), '--trials', '3', '--duration', '6']) == 0
    names = {p.name for p in tmp_path.iterdir()}
    assert names == {'fig7_trajectories.png', 'fig8_rmse.png', 'trials.csv',
                     'trajectories.csv', 'summary.md'}
    rows = (tmp_path / 'trials.csv').read_text().splitlines()
    assert rows[0].startswith('trial,rmse_x_mm') and len(rows) == 4
    assert (tmp_path / 'trajectories.csv').read_text().count('\n') == 32  # header + 31 samples
    assert '| 3 |' in (tmp_path / 'summary.md').read_text()


def test_experiment_rejects_a_bad_duration(tmp_path):
    with pytest.raises(SystemExit):
        main(['--out', str(tmp_path), '--duration', '0.1'])
