"""The knowledge build on Dask distributed: a real scheduler and worker processes on loopback.

The distributed build writes the same bytes as the local one (in this process and on the local
pool); a worker SIGKILLed mid-build loses only its block, which another worker learns again; a
client killed mid-build leaves a file that a distributed build resumes to the same bytes. An
unreachable scheduler, a worker of another version (there at the start, or joining mid-build)
and a full disk stop the build with the reason, and the file stays resumable.
"""

import concurrent.futures
import os
from pathlib import Path
import shutil
import signal
import subprocess

import dask
from dask_cluster import DaskCluster, filled_points, free_port, knowledge_build_command
from distributed import Client  # before dask.config.set: it loads Dask's distributed defaults
import pytest

from inflarm_bringup.knowledge_cli import knowledge_plant
import inflarm_control
from inflarm_control.knowledge import (
    ClusterError,
    KnowledgeGrid,
    build_knowledge_database,
)
from ros_harness import wait_until

pytestmark = pytest.mark.system  # a Dask scheduler and workers in processes of their own

# 96 points in 12 blocks of 8, 10 trials each: about 0.15 s per block on an idle core.
GRID = KnowledgeGrid(origin=(0.05, 0.06, 0.70), spacing=0.01, shape=(4, 4, 6))
BLOCK = 8
TRIALS = 10
BUILD = {'plant_factory': knowledge_plant, 'n_trials': TRIALS, 'batch_size': BLOCK,
         'progress': False}
BUILD_TIMEOUT_S = 120.0


def database_bytes(path) -> bytes:
    """A database's bytes: its metadata, codes and filled marks."""
    return b''.join((path / name).read_bytes()
                    for name in ('knowledge.json', 'codes.npy', 'filled.npy'))


@pytest.fixture(scope='module')
def local_bytes(tmp_path_factory):
    """The database of the build on the local pool of two processes, as bytes."""
    path = tmp_path_factory.mktemp('local') / 'knowledge'
    build_knowledge_database(path, GRID, workers=2, **BUILD).close()
    return database_bytes(path)


@pytest.fixture
def cluster(tmp_path):
    """A scheduler and two workers on loopback; killed afterwards, whatever the test did."""
    dask_cluster = DaskCluster(tmp_path / 'cluster')
    try:
        for _ in range(2):
            dask_cluster.add_worker()
        dask_cluster.wait_for_workers(2)
        yield dask_cluster
    finally:
        dask_cluster.stop()


def test_local_build_in_this_process_writes_the_pools_bytes(tmp_path, local_bytes):
    path = tmp_path / 'knowledge'
    build_knowledge_database(path, GRID, workers=1, **BUILD).close()
    assert database_bytes(path) == local_bytes


def test_build_on_dask_writes_the_local_builds_bytes(tmp_path, cluster, local_bytes):
    path = tmp_path / 'knowledge'
    db = build_knowledge_database(path, GRID, scheduler=cluster.address, **BUILD)
    assert db.n_filled == GRID.size
    db.close()
    assert database_bytes(path) == local_bytes


def test_a_worker_killed_mid_build_loses_only_its_block(tmp_path, cluster, local_bytes):
    path = tmp_path / 'knowledge'
    with Client(cluster.address, set_as_default=False) as observer, \
            concurrent.futures.ThreadPoolExecutor(1) as thread:
        (victim,) = [address for address, pid in observer.run(os.getpid).items()
                     if pid == cluster.workers[0].pid]
        build = thread.submit(build_knowledge_database, path, GRID, scheduler=cluster.address,
                              **BUILD)
        # Once a block is in and while the victim learns another one, SIGKILL it.
        assert wait_until(lambda: filled_points(path) >= 1 and observer.processing()[victim],
                          BUILD_TIMEOUT_S) or build.done(), 'the victim never held a block'
        done_before_kill = filled_points(path)
        cluster.workers[0].send_signal(signal.SIGKILL)
        cluster.workers[0].wait(timeout=10)
        db = build.result(timeout=BUILD_TIMEOUT_S)
    assert done_before_kill < GRID.size, 'the build finished before the kill'
    assert db.n_filled == GRID.size
    db.close()
    assert database_bytes(path) == local_bytes


def test_a_build_whose_client_is_killed_resumes_on_dask(tmp_path, cluster, local_bytes):
    path = tmp_path / 'knowledge'
    client = subprocess.Popen(knowledge_build_command(path, GRID, cluster.address, TRIALS, BLOCK))
    try:
        assert wait_until(lambda: filled_points(path) >= 2 or client.poll() is not None,
                          BUILD_TIMEOUT_S)
        client.send_signal(signal.SIGKILL)
    finally:
        client.kill()
        client.wait(timeout=10)
    interrupted = filled_points(path)
    assert 2 <= interrupted < GRID.size, 'the client finished before it was killed'
    assert interrupted % BLOCK == 0  # whole blocks only
    db = build_knowledge_database(path, GRID, scheduler=cluster.address, **BUILD)
    db.close()
    assert database_bytes(path) == local_bytes


def test_an_unreachable_scheduler_stops_the_build_naming_it(tmp_path, local_bytes):
    path = tmp_path / 'knowledge'
    address = f'tcp://127.0.0.1:{free_port()}'
    with dask.config.set({'distributed.comm.timeouts.connect': '2s'}), \
            pytest.raises(ClusterError, match=f'cannot reach the Dask scheduler at {address!r}'):
        build_knowledge_database(path, GRID, scheduler=address, **BUILD)
    assert filled_points(path) == 0
    build_knowledge_database(path, GRID, workers=2, **BUILD).close()  # resumable
    assert database_bytes(path) == local_bytes


def other_version(directory: Path) -> dict[str, str]:
    """Environment of a worker that imports a copy of inflarm_control with one line more in
    knowledge.py."""
    package = Path(inflarm_control.__file__).parent
    shutil.copytree(package, directory / 'inflarm_control',
                    ignore=shutil.ignore_patterns('*.pyc'))
    with open(directory / 'inflarm_control' / 'knowledge.py', 'a') as source:
        source.write('\n# another version\n')
    return {'PYTHONPATH': f"{directory}:{os.environ.get('PYTHONPATH', '')}"}


def test_a_worker_of_another_version_is_refused(tmp_path, local_bytes):
    dask_cluster = DaskCluster(tmp_path / 'cluster')
    try:
        dask_cluster.add_worker()
        dask_cluster.add_worker(environment=other_version(tmp_path / 'other'))
        dask_cluster.wait_for_workers(2)
        path = tmp_path / 'knowledge'
        with pytest.raises(ClusterError, match=r"Dask workers \['tcp://127\.0\.0\.1:\d+'\] of"
                           r" .* run another version of .*inflarm_control"):
            build_knowledge_database(path, GRID, scheduler=dask_cluster.address, **BUILD)
        assert filled_points(path) == 0
    finally:
        dask_cluster.stop()
    build_knowledge_database(path, GRID, workers=2, **BUILD).close()  # resumable
    assert database_bytes(path) == local_bytes


def test_a_worker_of_another_version_joining_mid_build_is_refused(tmp_path):
    path = tmp_path / 'knowledge'
    dask_cluster = DaskCluster(tmp_path / 'cluster')
    try:
        dask_cluster.add_worker()
        dask_cluster.wait_for_workers(1)
        with concurrent.futures.ThreadPoolExecutor(1) as thread:
            # 30 trials: blocks of ~0.5 s, so the build outlasts the second worker's start.
            build = thread.submit(build_knowledge_database, path, GRID,
                                  scheduler=dask_cluster.address, **{**BUILD, 'n_trials': 30})
            assert wait_until(lambda: filled_points(path) >= 1 or build.done(), BUILD_TIMEOUT_S)
            dask_cluster.add_worker(environment=other_version(tmp_path / 'other'))
            with pytest.raises(ClusterError, match=r'a block was learned on .* by another version'
                               r' of .*inflarm_control'):
                build.result(timeout=BUILD_TIMEOUT_S)
    finally:
        dask_cluster.stop()
    assert 1 <= filled_points(path) < GRID.size
    build_knowledge_database(path, GRID, workers=2, **{**BUILD, 'n_trials': 30}).close()
    assert filled_points(path) == GRID.size  # resumable


def test_a_full_disk_stops_the_build_and_the_database_resumes(tmp_path, local_bytes):
    # An 8 KiB tmpfs: no room for the database's files (each takes a page, the codes two).
    disk = tmp_path / 'disk'
    disk.mkdir()
    mount = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=8k', 'tmpfs', str(disk)],
                           capture_output=True, text=True)
    if mount.returncode != 0:
        pytest.skip(f'cannot mount a small tmpfs here (needs root): {mount.stderr.strip()}')
    try:
        path = disk / 'knowledge'
        with pytest.raises(OSError, match='cannot create the knowledge database .*No space'):
            build_knowledge_database(path, GRID, workers=2, **BUILD)
        assert not path.exists()  # half a database would not open
        # 20 KiB: room for the files, not for the 48 kB of codes
        subprocess.run(['mount', '-o', 'remount,size=20k', str(disk)], check=True)
        with pytest.raises(OSError, match='cannot reserve the \\d+ B of the knowledge database'
                           '.*No space left on device'):
            build_knowledge_database(path, GRID, workers=2, **BUILD)
        subprocess.run(['mount', '-o', 'remount,size=1m', str(disk)], check=True)
        build_knowledge_database(path, GRID, workers=2, **BUILD).close()
        assert database_bytes(path) == local_bytes
    finally:
        subprocess.run(['umount', '-l', str(disk)], check=False)
