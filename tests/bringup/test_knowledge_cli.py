"""inflarm-build-knowledge: builds a full-grid database a controller can open, reports failures."""

from inflarm_bringup.knowledge_cli import main
from inflarm_control.knowledge import KnowledgeDatabase, nearest_knowledge_point


def test_builds_a_database_for_every_knowledge_point(tmp_path, capsys):
    out = tmp_path / 'knowledge.db'
    assert main([str(out), '--trials', '1']) == 0
    assert '67200 knowledge points' in capsys.readouterr().out
    with KnowledgeDatabase.open(out) as db:
        assert db.n_filled == 67200
        point, memory = db.lookup((0.111, 0.098, 0.733))
        assert tuple(point) == tuple(nearest_knowledge_point((0.111, 0.098, 0.733)))
        assert memory.shape == (50, 5) and memory.max() > 0.0


def test_an_unwritable_output_fails_with_a_message(tmp_path, capsys):
    assert main([str(tmp_path / 'missing' / 'knowledge.db'), '--trials', '1']) == 1
    assert 'inflarm-build-knowledge:' in capsys.readouterr().err
