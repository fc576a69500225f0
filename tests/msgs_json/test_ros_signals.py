"""A stop request during a node's start-up (its imports, the building of its nodes): the process
exits 0 at once and quietly, even where the request lands in code that cannot raise it."""

import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.system  # node entry points in processes of their own

# A module whose import is interrupted inside a finalizer: what a C extension's callback does
# with it (scipy's Sobol tables, seen in the interrupt stress test) is the same, an
# "Exception ignored in ..." report instead of the exception.
VICTIM = """
import os, signal
class Victim:
    def __del__(self):
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(100_000):  # the handler runs here, inside __del__
            pass
Victim()
def main():
    print('main ran')
"""


def run_entry_point(tmp_path, module: str, source: str, **env) -> subprocess.CompletedProcess:
    """Run ``node_entry(module)`` in a fresh interpreter, ``module`` written from ``source``."""
    (tmp_path / f'{module}.py').write_text(source)
    code = ('import sys; sys.path.insert(0, sys.argv[1]); '
            f'from inflarm_msgs_json.ros.signals import node_entry; node_entry("{module}")()')
    return subprocess.run([sys.executable, '-c', code, str(tmp_path)], capture_output=True,
                          text=True, timeout=40, env=dict(os.environ, **env))


def test_a_stop_request_that_lands_where_it_cannot_raise_still_stops_quietly(tmp_path):
    run = run_entry_point(tmp_path, 'victim', VICTIM)
    assert run.returncode == 0, run.stderr
    assert 'main ran' not in run.stdout  # the stop request was kept
    assert 'Exception ignored' not in run.stderr and 'Traceback' not in run.stderr, run.stderr


# A node whose construction takes long (sim_mcu's camera renderer took seconds on a loaded
# machine, the interrupt stress test's slowest exit) and is stopped in the middle of it.
SLOW_NODE = """
import os, signal, time
from rclpy.node import Node
from inflarm_msgs_json.ros.spin import spin_node
class SlowToBuild(Node):
    def __init__(self):
        super().__init__('slow_to_build')
        self.create_publisher(__import__('std_msgs.msg').msg.String, 'chatter', 10)
        os.kill(os.getpid(), signal.SIGTERM)
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:  # a long build, in Python
            pass
        print('built')
def main():
    spin_node(SlowToBuild, [])
"""


def test_a_stop_request_while_a_node_is_built_stops_it_at_once(tmp_path, domain_id):
    # the build alone would take 60 s, longer than run_entry_point's timeout
    run = run_entry_point(tmp_path, 'slow_node', SLOW_NODE, ROS_DOMAIN_ID=str(domain_id))
    assert run.returncode == 0, run.stderr
    assert 'built' not in run.stdout
    assert 'Traceback' not in run.stderr and 'Warning' not in run.stderr, run.stderr


# What Cython does with an exception a `cdef` function cannot propagate, when it keeps the full
# traceback (scipy's Sobol tables, interrupted there in the stress test): PyErr_PrintEx, which
# hands it to sys.excepthook, then the unraisable report; the caller carries on.
CYTHON_VICTIM = """
import os, signal, sys
def interrupted():
    os.kill(os.getpid(), signal.SIGINT)
    for _ in range(100_000):  # the handler runs here
        pass
try:
    interrupted()
except BaseException as error:
    sys.excepthook(type(error), error, error.__traceback__)
    sys.unraisablehook(type('UnraisableHookArgs', (), dict(
        exc_type=type(error), exc_value=error, exc_traceback=error.__traceback__,
        err_msg=None, object='cython_victim.cdef_function'))())
def main():
    print('main ran')
"""


def test_a_stop_request_that_an_extension_reports_with_a_traceback_stops_quietly(tmp_path):
    run = run_entry_point(tmp_path, 'cython_victim', CYTHON_VICTIM)
    assert run.returncode == 0, run.stderr
    assert 'main ran' not in run.stdout
    assert 'StartupInterrupted' not in run.stderr and 'Traceback' not in run.stderr, run.stderr


# An object whose construction the stop request interrupts, kept by a registry, and whose
# finalizer then fails at exit for what its __init__ never set: what llvmlite's ObjectRef did
# when a load_estimator was stopped while numba loaded its kernels ("Exception ignored in:
# <function ObjectRef.__del__ ...> AttributeError: ... '_as_parameter_'", a run of the
# interrupt stress test).
HALF_BUILT_NODE = """
import os, signal
from rclpy.node import Node
from inflarm_msgs_json.ros.spin import spin_node
REGISTRY = []
class Handle:
    def __init__(self):
        REGISTRY.append(self)
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(100_000):  # the handler runs here, before the handle is set
            pass
        self._as_parameter_ = 1
    def __del__(self):
        del self._as_parameter_
class HalfBuilt(Node):
    def __init__(self):
        super().__init__('half_built')
        self.handle = Handle()
        print('built')
def main():
    spin_node(HalfBuilt, [])
"""


def test_objects_a_stop_request_left_half_built_do_not_report_at_exit(tmp_path, domain_id):
    run = run_entry_point(tmp_path, 'half_built', HALF_BUILT_NODE, ROS_DOMAIN_ID=str(domain_id))
    assert run.returncode == 0, run.stderr
    assert 'built' not in run.stdout
    assert 'Exception ignored' not in run.stderr and 'Traceback' not in run.stderr, run.stderr


# An import stopped between an extension taking an object over and its Python wrapper marking
# it owned: what llvmlite's ExecutionEngine.add_module does (LLVMPY_AddModule, then
# `module._owned = True`). Both would free the module: no finalizer may run after such a stop.
OWNED_TWICE = """
import os, signal
class Module:
    def __del__(self, write=os.write):
        write(1, b'module freed by its wrapper')
def add_module(module):
    os.kill(os.getpid(), signal.SIGTERM)  # the handler runs as this call returns
module = Module()
add_module(module)
module.owned = True
def main():
    print('main ran')
"""


def test_a_stop_request_during_the_imports_runs_no_finalizer(tmp_path):
    run = run_entry_point(tmp_path, 'owned_twice', OWNED_TWICE)
    assert run.returncode == 0, run.stderr
    assert 'main ran' not in run.stdout
    assert 'freed' not in run.stdout, run.stdout
    assert 'Traceback' not in run.stderr, run.stderr
