"""Tests of the experiential knowledge database (section 3.2 of 001_...)."""

import json
import os

import numpy as np
import pytest

from inflarm_bringup.knowledge_cli import knowledge_plant
from inflarm_control.knowledge import (
    DEFAULT_GRID,
    DEFAULT_SCALE_PA_PER_LSB,
    HOME_POINT,
    KnowledgeDatabase,
    KnowledgeGrid,
    build_knowledge_database,
    nearest_knowledge_point,
    seed_memory,
)
from inflarm_control.pid_ilc import PidIlcController, PidIlcParams, run_trials

# A 4 x 3 x 5 grid with a different spacing and origin from the default one.
SMALL = KnowledgeGrid(origin=(0.05, -0.02, 0.70), spacing=0.02, shape=(4, 3, 5))


def random_memory(rng, n, steps=50, full_scale=65535.0):
    return rng.uniform(0.0, full_scale, size=(n, steps, 5))


# --- grid ----------------------------------------------------------------------------------


def test_paper_example_snaps_to_whole_centimetres():
    np.testing.assert_allclose(
        nearest_knowledge_point((0.111, 0.098, 0.733)), (0.110, 0.100, 0.730), atol=1e-12
    )
    # The grid values themselves are exact to the float nearest the decimal.
    assert nearest_knowledge_point((0.111, 0.098, 0.733)).tolist() == [0.11, 0.1, 0.73]


def test_default_grid_is_the_papers_67200_points():
    points = DEFAULT_GRID.points()
    assert points.shape == (67_200, 3)
    xs, ys, zs = (np.unique(points[:, k]) for k in range(3))
    np.testing.assert_allclose(xs, np.arange(-19, 21) / 100, atol=1e-12)
    np.testing.assert_allclose(ys, np.arange(-19, 21) / 100, atol=1e-12)
    np.testing.assert_allclose(zs, np.arange(58, 100) / 100, atol=1e-12)
    # Flat index order is C order over (ix, iy, iz).
    np.testing.assert_allclose(points[1] - points[0], (0.0, 0.0, 0.01), atol=1e-12)
    np.testing.assert_allclose(points[42] - points[0], (0.0, 0.01, 0.0), atol=1e-12)


@pytest.mark.parametrize('grid', [DEFAULT_GRID, SMALL])
def test_index_of_inverts_point_of_within_half_a_cell(grid):
    rng = np.random.default_rng(7)
    points = grid.points()
    np.testing.assert_array_equal(grid.index_of(points), np.arange(grid.size))
    jitter = rng.uniform(-0.49, 0.49, size=points.shape) * grid.spacing
    np.testing.assert_array_equal(grid.index_of(points + jitter), np.arange(grid.size))
    assert grid.index_of(points[5] + jitter[5]) == 5


def test_nearest_matches_brute_force_search():
    rng = np.random.default_rng(7)
    lower, upper = np.array(SMALL.lower), np.array(SMALL.upper)
    targets = rng.uniform(lower, upper - 1e-9, size=(500, 3))
    points = SMALL.points()
    brute = points[np.argmin(np.linalg.norm(targets[:, None] - points[None], axis=2), axis=1)]
    np.testing.assert_allclose(SMALL.nearest(targets), brute, atol=1e-12)
    single = np.array([SMALL.nearest(t) for t in targets[:20]])
    np.testing.assert_allclose(single, brute[:20], atol=1e-12)
    np.testing.assert_allclose(nearest_knowledge_point(targets, SMALL), brute, atol=1e-12)


def test_covered_box_is_half_a_cell_around_the_grid():
    np.testing.assert_allclose(DEFAULT_GRID.lower, (-0.195, -0.195, 0.575), atol=1e-12)
    np.testing.assert_allclose(DEFAULT_GRID.upper, (0.205, 0.205, 0.995), atol=1e-12)
    # The inclusive lower corner survives float error.
    np.testing.assert_allclose(
        nearest_knowledge_point((-0.195, -0.195, 0.575)), (-0.19, -0.19, 0.58), atol=1e-12
    )


@pytest.mark.parametrize(
    ('point', 'match'),
    [
        ((0.205, 0.0, 0.7), r'x in \[-0\.1950, 0\.2050\) m'),
        ((0.0, -0.1951, 0.7), r'y in \[-0\.1950, 0\.2050\) m'),
        ((0.0, 0.0, 0.574), r'z in \[0\.5750, 0\.9950\) m'),
        ((0.0, 0.0, 1.2), r'z in \[0\.5750, 0\.9950\) m.*got 1\.2'),
        ((111.0, 98.0, 733.0), r'x in .* got 111\.0'),  # millimetres are not metres
    ],
)
def test_points_outside_the_grid_are_rejected_naming_the_bound(point, match):
    with pytest.raises(ValueError, match=match):
        nearest_knowledge_point(point)
    with pytest.raises(ValueError, match=match):
        nearest_knowledge_point(np.array([(0.0, 0.0, 0.7), point]))


@pytest.mark.parametrize(
    ('point', 'match'),
    [
        ((0.0, 0.7), r'shape \(3,\)'),
        (np.zeros((2, 4)), r'shape \(3,\) or \(N, 3\)'),
        ((0.0, np.nan, 0.7), 'finite'),
        (np.array([[0.0, np.inf, 0.7]]), 'finite'),
    ],
)
def test_malformed_points_are_rejected(point, match):
    with pytest.raises(ValueError, match=match):
        nearest_knowledge_point(point)


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'spacing': 0.0}, 'spacing > 0'),
        ({'spacing': np.nan}, 'spacing > 0'),
        ({'shape': (40, 0, 42)}, 'shape of 3 positive ints'),
        ({'shape': (40, 40)}, 'shape of 3 positive ints'),
        ({'origin': (0.0, 0.0)}, 'origin of 3 finite floats'),
    ],
)
def test_grid_validates_its_fields(kwargs, match):
    with pytest.raises(ValueError, match=match):
        KnowledgeGrid(**kwargs)


def test_nearest_knowledge_point_needs_a_grid():
    with pytest.raises(ValueError, match='grid to be a KnowledgeGrid'):
        nearest_knowledge_point((0.1, 0.1, 0.7), grid=(40, 40, 42))


def test_closed_database_refuses_use(tmp_path):
    db = KnowledgeDatabase.create(tmp_path / 'k', SMALL)
    db.close()
    with pytest.raises(ValueError, match='is closed'):
        db.lookup((0.05, -0.02, 0.70))
    with pytest.raises(ValueError, match='is closed'):
        db.write(0, np.zeros((50, 5)))


def test_point_of_rejects_indices_outside_the_grid():
    with pytest.raises(ValueError, match=r'index in \[0, 60\), got 60'):
        SMALL.point_of(60)
    with pytest.raises(ValueError, match=r'index as int'):
        SMALL.point_of(1.5)


# --- database file ------------------------------------------------------------------------


def test_round_trip_is_within_half_an_lsb(tmp_path):
    rng = np.random.default_rng(7)
    scale = 2.5  # Pa per LSB
    memory = random_memory(rng, SMALL.size, steps=8, full_scale=65535 * scale)
    with KnowledgeDatabase.create(tmp_path / 'k', SMALL, steps=8, scale=scale) as db:
        db.write(np.arange(SMALL.size), memory)
    db = KnowledgeDatabase.open(tmp_path / 'k')
    assert (db.grid, db.steps, db.rate_hz, db.scale) == (SMALL, 8, 5.0, 2.5)
    back = db.read(np.arange(SMALL.size))
    np.testing.assert_allclose(back, memory, rtol=0.0, atol=scale / 2 + 1e-9)
    assert np.max(np.abs(back - memory)) > 0.4 * scale  # really quantized, not stored as float


def test_pressures_are_clamped_to_the_code_range(tmp_path):
    db = KnowledgeDatabase.create(tmp_path / 'k', SMALL, steps=2, scale=10.0)
    memory = np.array([[-500.0, -4.0, 4.0, 6.0, 655_349.0], [655_360.0, 1e9, 0.0, 15.0, 25.0]])
    db.write(3, memory)
    expected = [[0.0, 0.0, 0.0, 10.0, 655_350.0], [655_350.0, 655_350.0, 0.0, 20.0, 20.0]]
    np.testing.assert_allclose(db.read(3), expected)  # round half to even: 15 -> 20, 25 -> 20


def test_lookup_returns_the_nearest_points_memory(tmp_path):
    rng = np.random.default_rng(7)
    memory = random_memory(rng, SMALL.size)
    db = KnowledgeDatabase.create(tmp_path / 'k', SMALL)
    db.write(np.arange(SMALL.size), memory)
    target = np.array((0.111, 0.013, 0.733))
    point, got = db.lookup(target)
    np.testing.assert_allclose(point, (0.11, 0.02, 0.74), atol=1e-12)
    index = SMALL.index_of(point)
    assert index == SMALL.index_of(target)
    assert got.shape == (50, 5) and got.dtype == np.float64
    np.testing.assert_allclose(got, memory[index], atol=DEFAULT_SCALE_PA_PER_LSB / 2 + 1e-9)
    np.testing.assert_allclose(db.lookup(list(target))[1], got)
    with pytest.raises(ValueError, match=r'z in \[0\.6900, 0\.7900\)'):
        db.lookup((0.111, 0.013, 0.80))


def test_filled_mask_tracks_writes_and_survives_reopening(tmp_path):
    rng = np.random.default_rng(7)
    db = KnowledgeDatabase.create(tmp_path / 'k', SMALL)
    assert db.n_filled == 0 and not db.has(7)
    with pytest.raises(KeyError, match='holds no memory'):
        db.lookup(SMALL.point_of(7))
    db.write([7, 11], random_memory(rng, 2))
    assert db.has(7) and db.has(11) and not db.has(8)
    db.close()
    db = KnowledgeDatabase.open(tmp_path / 'k')
    np.testing.assert_array_equal(np.flatnonzero(db.filled), [7, 11])
    assert db.n_filled == 2
    with pytest.raises(ValueError, match='read-only'):
        db.filled[0] = True
    with pytest.raises(KeyError, match='index 8 holds no memory'):
        db.read([7, 8])


def test_full_size_database_holds_the_papers_32_mib_in_standard_npy_files(tmp_path):
    db = KnowledgeDatabase.create(tmp_path / 'k', steps=50)
    data_bytes = 67_200 * 50 * 5 * 2
    assert data_bytes == 33_600_000
    rng = np.random.default_rng(7)
    memory = random_memory(rng, 1)[0]
    db.write(67_199, memory)
    db.close()
    # numpy alone reads it: the codes, the marks, the metadata
    codes = np.load(tmp_path / 'k' / 'codes.npy', mmap_mode='r')
    assert codes.dtype == np.dtype('<u2') and codes.shape == (67_200, 50, 5)
    assert codes.nbytes == data_bytes
    filled = np.load(tmp_path / 'k' / 'filled.npy')
    np.testing.assert_array_equal(np.flatnonzero(filled), [67_199])
    metadata = json.loads((tmp_path / 'k' / 'knowledge.json').read_text())
    assert metadata['grid']['shape'] == [40, 40, 42] and metadata['scale_pa_per_lsb'] == 15.0
    np.testing.assert_allclose(codes[67_199] * metadata['scale_pa_per_lsb'], memory,
                               atol=DEFAULT_SCALE_PA_PER_LSB / 2 + 1e-9)
    db = KnowledgeDatabase.open(tmp_path / 'k')
    np.testing.assert_allclose(
        db.lookup((0.2, 0.2, 0.99))[1], memory, atol=DEFAULT_SCALE_PA_PER_LSB / 2 + 1e-9
    )


def test_write_validates_its_arguments(tmp_path):
    db = KnowledgeDatabase.create(tmp_path / 'k', SMALL, steps=4)
    with pytest.raises(ValueError, match=r'memory of shape \(2, 4, 5\)'):
        db.write([0, 1], np.zeros((2, 50, 5)))
    with pytest.raises(ValueError, match='finite memory'):
        db.write(0, np.full((4, 5), np.nan))
    with pytest.raises(ValueError, match=r'index in \[0, 60\), got -1'):
        db.write(-1, np.zeros((4, 5)))
    assert db.n_filled == 0
    db.close()
    ro = KnowledgeDatabase.open(tmp_path / 'k', mode='r')
    with pytest.raises(ValueError, match="mode 'r\\+'"):
        ro.write(0, np.zeros((4, 5)))


def test_create_validates_its_arguments(tmp_path):
    KnowledgeDatabase.create(tmp_path / 'k', SMALL).close()
    with pytest.raises(ValueError, match='path to not exist'):
        KnowledgeDatabase.create(tmp_path / 'k', SMALL)
    KnowledgeDatabase.create(tmp_path / 'k', SMALL, steps=3, overwrite=True).close()
    assert KnowledgeDatabase.open(tmp_path / 'k').steps == 3
    with pytest.raises(ValueError, match='scale > 0'):
        KnowledgeDatabase.create(tmp_path / 'x.db', SMALL, scale=0.0)
    with pytest.raises(ValueError, match='rate_hz > 0'):
        KnowledgeDatabase.create(tmp_path / 'x.db', SMALL, rate_hz=-5.0)
    with pytest.raises(ValueError, match='steps to be a positive int'):
        KnowledgeDatabase.create(tmp_path / 'x.db', SMALL, steps=0)
    with pytest.raises(ValueError, match='grid to be a KnowledgeGrid'):
        KnowledgeDatabase.create(tmp_path / 'x.db', (40, 40, 42))


def test_a_database_appears_whole_to_a_reader_that_opens_it_while_it_is_created(
        tmp_path, monkeypatch):
    path = tmp_path / 'k'
    seen_while_creating = []
    open_memmap = np.lib.format.open_memmap

    def open_memmap_and_look(*args, **kwargs):
        seen_while_creating.append(path.exists())
        return open_memmap(*args, **kwargs)

    monkeypatch.setattr(np.lib.format, 'open_memmap', open_memmap_and_look)
    with KnowledgeDatabase.create(path, SMALL) as db:
        db.write([5], np.full((1, db.steps, 5), 1000.0))
    assert seen_while_creating == [False, False]
    assert sorted(p.name for p in tmp_path.iterdir()) == ['k']  # no staging left behind
    with KnowledgeDatabase.open(path) as db:
        assert db.n_filled == 1


def test_open_rejects_what_is_not_a_database_and_truncated_or_mismatched_arrays(tmp_path):
    path = tmp_path / 'k'
    KnowledgeDatabase.create(path, SMALL).close()
    with pytest.raises(ValueError, match="mode 'r' or 'r\\+'"):
        KnowledgeDatabase.open(path, mode='w')
    with pytest.raises(ValueError, match='expected a knowledge database directory'):
        KnowledgeDatabase.open(tmp_path / 'missing')
    other = tmp_path / 'other.npy'
    np.save(other, np.zeros(1000))
    with pytest.raises(ValueError, match='expected a knowledge database directory'):
        KnowledgeDatabase.open(other)

    codes = path / 'codes.npy'
    written = codes.read_bytes()
    for size in (len(written) - 2, 0):
        os.truncate(codes, size)
        with pytest.raises(ValueError, match='codes.npy.* cannot be mapped'):
            KnowledgeDatabase.open(path)
    codes.write_bytes(written)
    KnowledgeDatabase.open(path).close()

    np.save(path / 'filled.npy', np.zeros(SMALL.size + 1, dtype=bool))
    with pytest.raises(ValueError, match=rf'filled.npy.* of bool \({SMALL.size},\), got bool '
                                         rf'\({SMALL.size + 1},\)'):
        KnowledgeDatabase.open(path)


def test_open_rejects_a_garbled_mask_another_format_and_names_a_format_1_file(tmp_path):
    path = tmp_path / 'k'
    KnowledgeDatabase.create(path, SMALL).close()
    mask = np.zeros(SMALL.size, dtype=np.uint8)
    mask[3] = 7
    np.save(path / 'filled.npy', mask.view(bool))
    with pytest.raises(ValueError, match='corrupt filled mask'):
        KnowledgeDatabase.open(path)
    metadata = json.loads((path / 'knowledge.json').read_text())
    (path / 'knowledge.json').write_text(json.dumps({**metadata, 'format': 3}))
    with pytest.raises(ValueError, match='format 2 at .*, got 3'):
        KnowledgeDatabase.open(path)
    (path / 'knowledge.json').write_text(json.dumps({**metadata, 'steps': 'fifty'}))
    with pytest.raises(ValueError, match='inconsistent metadata'):
        KnowledgeDatabase.open(path)
    old = tmp_path / 'old.db'
    old.write_bytes(b'INFLKDB\x00' + bytes(120))
    with pytest.raises(ValueError, match='format 1 .*rebuild it with inflarm-build-knowledge'):
        KnowledgeDatabase.open(old)


# --- building and seeding -------------------------------------------------------------------

# Around the paper's example target (111, 98, 733) mm: 3 x 3 x 3 knowledge points, 1 cm apart.
AROUND = KnowledgeGrid(origin=(0.10, 0.09, 0.72), spacing=0.01, shape=(3, 3, 3))


@pytest.fixture(scope='module')
def built(tmp_path_factory):
    path = tmp_path_factory.mktemp('kdb') / 'around'
    db = build_knowledge_database(path, AROUND, plant_factory=knowledge_plant, batch_size=10,
                                  workers=1, progress=False)
    yield db
    db.close()


def test_build_fills_every_point_with_the_last_trials_memory(built):
    assert built.n_filled == AROUND.size
    assert (built.steps, built.rate_hz, built.scale) == (50, 5.0, DEFAULT_SCALE_PA_PER_LSB)
    memory = built.read(np.arange(AROUND.size))
    assert memory.shape == (27, 50, 5)
    # the PEA's memory starts at its cap (100 kPa), stored to the nearest LSB
    assert memory.min() >= 0.0
    assert memory.max() <= max(PidIlcParams().p_max) + DEFAULT_SCALE_PA_PER_LSB / 2
    # All targets are in quadrant 1: only PEA, B3 (y) and B4 (x) are driven.
    np.testing.assert_array_equal(memory[:, :, [1, 2]], 0.0)
    assert np.all(memory[:, :, [0, 3, 4]].max(axis=1) > 1e3)
    # The same 30 trials run directly give the stored memory, to half an LSB.
    index = AROUND.index_of((0.11, 0.10, 0.73))
    result = run_trials(
        knowledge_plant(1), PidIlcController(1), HOME_POINT, AROUND.point_of(index), 30, 20.0
    )
    half_lsb = DEFAULT_SCALE_PA_PER_LSB / 2 + 1e-9
    np.testing.assert_allclose(built.read(index), result.memory[0], atol=half_lsb)


def test_seeded_first_trial_reaches_sooner_than_pid(built):
    # The paper's example and a target 4.5 mm off its knowledge point on every axis.
    targets = np.array([(0.111, 0.098, 0.733), (0.1045, 0.0945, 0.7245)])
    np.testing.assert_allclose(
        nearest_knowledge_point(targets), [(0.11, 0.10, 0.73), (0.10, 0.09, 0.72)], atol=1e-12
    )
    memory = seed_memory(built, targets)
    seeded = run_trials(knowledge_plant(2), PidIlcController(2), HOME_POINT, targets, 1, 20.0,
                        memory=memory, keep_trajectories=False)
    pid = run_trials(knowledge_plant(2), PidIlcController(2), HOME_POINT, targets, 1, 20.0,
                     keep_trajectories=False)
    reach_seeded, reach_pid = seeded.reach_time[0], pid.reach_time[0]  # (2 tasks, 3 axes) [s]
    # the paper's example within 10 s (its conclusion: 8 s); 4.5 mm off the knowledge point,
    # the slow PID (3 kPa/m on z) takes the rest of z's way (measured: 13.2 s; the README)
    assert np.all(reach_seeded[0] <= 10.0), reach_seeded
    assert np.all(reach_seeded[1] <= 15.0), reach_seeded
    assert np.all(reach_seeded.max(axis=1) < reach_pid.max(axis=1)), (reach_seeded, reach_pid)
    assert np.all(seeded.rmse[0] < pid.rmse[0])


def test_build_resumes_only_the_missing_points(tmp_path, built):
    path = tmp_path / 'k'
    with KnowledgeDatabase.create(path, AROUND) as db:
        db.write([0, 26], np.full((2, 50, 5), 150.0))
    db = build_knowledge_database(
        path, AROUND, plant_factory=knowledge_plant, n_trials=30, batch_size=13, workers=1,
        progress=False
    )
    assert db.n_filled == 27
    np.testing.assert_allclose(db.read([0, 26]), 150.0)
    np.testing.assert_allclose(db.read(np.arange(1, 26)), built.read(np.arange(1, 26)))


def test_build_in_two_processes_matches_one(tmp_path, built):
    db = build_knowledge_database(
        tmp_path / 'k', AROUND, plant_factory=knowledge_plant, batch_size=14, workers=2,
        progress=False
    )
    np.testing.assert_allclose(db.read(np.arange(27)), built.read(np.arange(27)))


def test_build_validates_its_arguments(tmp_path):
    with pytest.raises(ValueError, match='n_trials to be an int >= 1'):
        build_knowledge_database(tmp_path / 'k', AROUND, plant_factory=knowledge_plant,
                                 n_trials=0)
    with pytest.raises(ValueError, match=r'scale >= 1\.526 Pa per LSB'):
        build_knowledge_database(tmp_path / 'k', AROUND, plant_factory=knowledge_plant,
                                 scale=1.0)
    KnowledgeDatabase.create(tmp_path / 'k', AROUND, steps=10).close()
    with pytest.raises(ValueError, match='to resume'):
        build_knowledge_database(tmp_path / 'k', AROUND, plant_factory=knowledge_plant,
                                 progress=False)


def test_seed_memory_is_the_nearest_points_memory(built):
    target = (0.111, 0.098, 0.733)
    np.testing.assert_allclose(seed_memory(built, target), built.lookup(target)[1])
    np.testing.assert_allclose(
        seed_memory(built, [target, (0.10, 0.11, 0.74)]),
        built.read(AROUND.index_of([(0.11, 0.10, 0.73), (0.10, 0.11, 0.74)])),
    )
    with pytest.raises(ValueError, match=r'x in \[0\.0950, 0\.1250\)'):
        seed_memory(built, (0.2, 0.10, 0.73))
    with pytest.raises(ValueError, match='db to be a KnowledgeDatabase'):
        seed_memory(str(built.path), target)
    empty = KnowledgeDatabase.create(built.path.with_name('empty'), AROUND)
    with pytest.raises(KeyError, match='holds no memory'):
        seed_memory(empty, target)
