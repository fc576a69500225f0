"""inflarm-build-knowledge: builds a full-grid database a controller can open, reports failures."""

import numpy as np

from inflarm_bringup.knowledge_cli import main
from inflarm_control.knowledge import KnowledgeDatabase

# The paper's grid (3.2 of 001_): x and y from -0.19 m, z from 0.58 m, 1 cm apart; 40 x 40 x 42
# points, flat index (ix * 40 + iy) * 42 + iz. The paper's example target (111, 98, 733) mm is
# nearest to the grid point (110, 100, 730) mm: ix = 30, iy = 29, iz = 15.
TARGET = (0.111, 0.098, 0.733)
NEAREST = (0.11, 0.10, 0.73)
NEAREST_INDEX = (30 * 40 + 29) * 42 + 15


def test_builds_a_database_for_every_knowledge_point(tmp_path, capsys):
    out = tmp_path / 'knowledge.db'
    assert main([str(out), '--trials', '1']) == 0
    assert '67200 knowledge points' in capsys.readouterr().out
    with KnowledgeDatabase.open(out) as db:
        assert db.n_filled == 67200
        point, memory = db.lookup(TARGET)
        np.testing.assert_allclose(point, NEAREST, rtol=0, atol=1e-12)
        assert memory.shape == (50, 5) and memory.max() > 0.0
        # the memory stored at that point's index, not a neighbour's
        np.testing.assert_array_equal(memory, db.read([NEAREST_INDEX])[0])
        assert not np.array_equal(memory, db.read([NEAREST_INDEX + 1])[0])


def test_an_unwritable_output_fails_with_a_message(tmp_path, capsys):
    assert main([str(tmp_path / 'missing' / 'knowledge.db'), '--trials', '1']) == 1
    assert 'inflarm-build-knowledge:' in capsys.readouterr().err
