"""The demo's ``--seed`` reaches every simulator of its system, on either backend."""

import importlib
import pathlib

import pytest

from inflarm_bringup.demo import demo_nodes
from inflarm_bringup.systems import Backend


def declared(node) -> set[str]:
    """The parameter names the node's module declares."""
    module = importlib.import_module(f'{node.package}.nodes.{node.executable}')
    return {p.name for p in getattr(module, 'PARAMETERS', ())}


@pytest.mark.parametrize('backend', [Backend('sim'), Backend('sim_mcu', '/tmp/inflarm-mcu')])
def test_every_node_with_a_seed_gets_the_demo_s(backend, tmp_path: pathlib.Path):
    nodes = demo_nodes(backend, tmp_path / 'knowledge', 3, tmp_path / 'bag', 'sqlite3')
    seeded = [n for n in nodes if 'seed' in declared(n)]
    # arm_sim and sra_sim, or sim_mcu (both arms behind the bridge)
    assert {n.executable for n in seeded} == (
        {'sim_mcu'} if backend.kind == 'sim_mcu' else {'arm_sim', 'sra_sim'})
    for node in seeded:
        assert node.parameters.get('seed') == 3, (node.executable, node.parameters)
    (controller,) = (n for n in nodes if n.executable == 'pressure_controller')
    assert controller.parameters['knowledge_db_path'] == str(tmp_path / 'knowledge')
