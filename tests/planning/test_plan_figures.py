"""inflarm-plan-figures: Figs 10 and 12 and the summary of the paper's scenario."""

import re

from inflarm_planning import plan_figures
from inflarm_planning.scenario import ALERT_MARGIN


def test_the_figures_and_summary_are_written(tmp_path, capsys):
    assert plan_figures.main(['--out', str(tmp_path), '--resolution', '0.01']) == 0
    for name in ('fig10_path.png', 'fig12_distance.png'):
        data = (tmp_path / name).read_bytes()
        assert data.startswith(b'\x89PNG') and len(data) > 20_000
    summary = (tmp_path / 'summary.md').read_text()
    assert summary in capsys.readouterr().out
    lengths = {name: float(value) for name, value in re.findall(
        r"\| grid path, cost '(\w+)'.*? \| ([\d.]+) mm \|", summary)}
    assert set(lengths) == {'length', 'paper'}
    assert 230.0 < lengths['length'] <= lengths['paper'] < 300.0
    clearance = float(re.search(r'end to obstacle, trajectory \(min\) \| ([\d.]+) mm',
                                summary).group(1))
    assert clearance >= ALERT_MARGIN * 1e3 - 0.05  # printed to 0.1 mm
