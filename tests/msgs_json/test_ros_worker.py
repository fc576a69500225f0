"""LatestJobWorker: jobs off the caller's thread, the newest waiting one first, failures
delivered as results, nothing delivered after close."""

import threading

from inflarm_msgs_json.ros.worker import LatestJobWorker


def blocking_worker():
    release = threading.Event()
    started: list[str] = []
    notified: list[int] = []

    def run(job: str) -> str:
        started.append(job)
        if job == 'first':
            assert release.wait(30.0)
        if job == 'bad':
            raise ValueError('bad job')
        return f'{job} done'

    worker = LatestJobWorker('test worker', run, lambda: notified.append(1))
    return worker, release, started, notified


def test_a_job_waiting_behind_a_running_one_is_replaced_by_a_newer_one():
    worker, release, started, notified = blocking_worker()
    assert worker.submit('first') is False
    assert worker.busy
    assert worker.submit('second') is False  # waits while 'first' runs
    assert worker.submit('third') is True  # replaces 'second'
    release.set()
    assert worker.wait(30.0)
    assert not worker.busy
    assert started == ['first', 'third']
    assert worker.results() == ['first done', 'third done']
    assert worker.results() == []
    assert len(notified) == 2


def test_what_a_job_raises_is_its_result_and_the_worker_goes_on():
    worker, release, _, _ = blocking_worker()
    release.set()
    worker.submit('bad')
    assert worker.wait(30.0)
    worker.submit('good')
    assert worker.wait(30.0)
    bad, good = worker.results()
    assert isinstance(bad, ValueError) and str(bad) == 'bad job'
    assert good == 'good done'


def test_after_close_a_running_job_delivers_nothing_and_new_ones_are_ignored():
    worker, release, started, notified = blocking_worker()
    worker.submit('first')
    worker.submit('second')
    worker.close(0.0)  # 'first' is still running: not waited for
    release.set()
    assert worker.wait(30.0)
    assert worker.submit('third') is False
    assert started == ['first'] and worker.results() == [] and notified == []
