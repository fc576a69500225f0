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
    out = tmp_path / 'knowledge'
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
    assert main([str(tmp_path / 'missing' / 'knowledge'), '--trials', '1']) == 1
    assert 'inflarm-build-knowledge:' in capsys.readouterr().err


def test_an_unreachable_scheduler_exits_2_naming_it(tmp_path, capsys):
    import dask
    from dask_cluster import free_port
    import distributed  # noqa: F401 - loads its config defaults before dask.config.set

    address = f'tcp://127.0.0.1:{free_port()}'
    with dask.config.set({'distributed.comm.timeouts.connect': '1s'}):
        assert main([str(tmp_path / 'knowledge'), '--scheduler', address]) == 2
    err = capsys.readouterr().err
    assert f'inflarm-build-knowledge: cannot reach the Dask scheduler at {address!r}' in err


def test_workers_and_a_scheduler_together_are_refused(tmp_path, capsys):
    assert main([str(tmp_path / 'knowledge'), '--scheduler', 'tcp://127.0.0.1:8786',
                 '--workers', '2']) == 1
    assert 'expected workers=None with a scheduler' in capsys.readouterr().err
