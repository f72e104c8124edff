"""The first start of the physics: compiled once per install location, by a command ahead of
time or by the first start (which says so), and never again by a later start.

The end-to-end tests run from an install made as colcon makes it (sphere_twin.scratch_install),
with numba's cache in that install: it compiles once for the module (about a minute).
"""

import contextlib
import importlib
import os
import re
import subprocess
import sys
from pathlib import Path

import numba
import pytest

from msg_defs.topics import SURFACE_NORMAL
from sphere_sim.twin import kernel_cache, precompile
from sphere_sim.twin.kernel_cache import (
    KERNEL_MODULES,
    STUDY_KERNEL_MODULES,
    cached_kernels,
    has_machine_code,
)
from sphere_sim.twin.precompile import COMPILED_LINE, COMPILING_LINE, announce_compile
from sphere_twin.commands.compile import NOT_COMPILED_STATUS
from sphere_twin.processes import parameter_args
from sphere_twin.scratch_install import install_into

ROOT = Path(__file__).resolve().parents[1]
# Budgets that only stop a stuck run: a cold compile takes a minute or two on a loaded 2-core
# machine, a warm start seconds.
COMPILE_TIMEOUT_S = 900.0
CHECK_TIMEOUT_S = 120.0
FIRST_MESSAGE_TIMEOUT_S = 120.0


# --- the detector, on a kernel of the test's own ---------------------------------------------
KERNEL_SOURCE = '''
import numba


@numba.njit(cache=True)
def twice(x):
    return {factor} * x
'''


def _import_fresh(directory, factor):
    """Write the kernel module with ``factor`` and import it anew (a new dispatcher, as a new
    process would make)."""
    (directory / 'first_start_kernel.py').write_text(KERNEL_SOURCE.format(factor=factor))
    sys.modules.pop('first_start_kernel', None)
    importlib.invalidate_caches()
    return importlib.import_module('first_start_kernel').twice


@pytest.fixture
def own_kernel_dir(tmp_path, monkeypatch):
    # numba's in-tree cache: beside the module, in tmp_path (a NUMBA_CACHE_DIR of the caller's
    # would outlive the test).
    monkeypatch.setattr(numba.config, 'CACHE_DIR', '')
    # No .pyc: a rewrite within the same second and of the same size would load stale bytecode.
    monkeypatch.setattr(sys, 'dont_write_bytecode', True)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    sys.modules.pop('first_start_kernel', None)


def test_a_kernel_is_cached_once_called_and_until_its_source_or_cache_changes(own_kernel_dir):
    twice = _import_fresh(own_kernel_dir, 2.0)
    assert not has_machine_code(twice)
    twice(1.5)
    assert has_machine_code(twice)
    # What a new process finds: the cache numba wrote.
    assert has_machine_code(_import_fresh(own_kernel_dir, 2.0))
    # An edited source is compiled anew (numba keys its cache on the source's content).
    assert not has_machine_code(_import_fresh(own_kernel_dir, 3.0))
    twice = _import_fresh(own_kernel_dir, 2.0)
    assert has_machine_code(twice)
    # `make clean-cache` removes the machine code: numba would compile again.
    for data in (own_kernel_dir / '__pycache__').glob('*.nbc'):
        data.unlink()
    assert not has_machine_code(twice)


def test_a_kernel_without_a_disk_cache_never_counts_as_cached():
    @numba.njit
    def uncached(x):
        return x + 1.0

    uncached(1.0)
    assert not has_machine_code(uncached)


def test_every_module_with_a_cached_kernel_is_listed():
    decorator = re.compile(r'^@numba\.n?jit\(.*cache=True', re.MULTILINE)
    in_source = set()
    for package in ('msg_defs', 'sphere_sim', 'sphere_control', 'sphere_twin'):
        for path in (ROOT / package).rglob('*.py'):
            if decorator.search(path.read_text()):
                in_source.add('.'.join(path.relative_to(ROOT).with_suffix('').parts))
    assert in_source == set(KERNEL_MODULES) | set(STUDY_KERNEL_MODULES)
    assert not set(KERNEL_MODULES) & set(STUDY_KERNEL_MODULES)


def test_the_kernels_are_those_numba_compiles_on_their_own():
    names = {kernel_cache.kernel_name(d) for d in cached_kernels()}
    assert 'sphere_sim.integrate.radau_compiled.integrate' in names
    assert 'sphere_sim.model.dynamics.rhs_kernel' in names
    # inline='always': compiled into the callers, never cached on its own.
    assert 'sphere_sim.model.vec3.dot' not in names


# --- the cold-start announcement, with the cache's answer given --------------------------------
@pytest.fixture
def announced(monkeypatch):
    """(cold: bool) -> (lines logged, compile calls): the cache answers ``cold``."""
    lines, compiles = [], []

    def fake_compile():
        compiles.append(True)
        return precompile.CompileReport(65, 1.0, False, (), (Path('/cache'),))

    def answer(cold):
        monkeypatch.setattr(precompile, 'physics_compiled', lambda: not cold)
        monkeypatch.setattr(precompile, 'compile_physics', fake_compile)
        return lines, compiles

    return answer


def test_a_warm_start_says_nothing_and_compiles_nothing(announced):
    lines, compiles = announced(cold=False)
    with announce_compile(lines.append):
        pass
    assert (lines, compiles) == ([], [])


def test_a_cold_start_says_what_it_does_compiles_and_says_how_long_it_took(announced):
    lines, compiles = announced(cold=True)
    with announce_compile(lines.append):
        assert len(lines) == 1  # said before the physics loads
    assert compiles == [True]
    assert len(lines) == 2
    assert lines[0].startswith(COMPILING_LINE) and 'once' in lines[0]
    assert str(precompile.install_location()) in lines[0]
    assert lines[1].startswith(COMPILED_LINE) and '/cache' in lines[1]


def test_a_start_that_fails_loading_the_physics_compiles_no_further(announced):
    lines, compiles = announced(cold=True)
    with pytest.raises(ValueError, match='no_such_scene'), announce_compile(lines.append):
        raise ValueError('no scene no_such_scene')
    assert compiles == []
    assert len(lines) == 1


# --- end to end, from an install location ------------------------------------------------------
# The install and its compile are made once for the module. The node test among these measures
# nothing in wall time but a two-minute budget, so make test runs it in its two-worker pass, on
# the worker that made the compile (`load_tolerant`).
@pytest.fixture(scope='module')
def install(tmp_path_factory):
    return install_into(tmp_path_factory.mktemp('first_start') / 'install')


def _run(install, executable, *args, timeout_s):
    env = {**os.environ, **install.environment()}
    return subprocess.run([str(install.executable(executable)), *args], env=env,
                          cwd=install.prefix, capture_output=True, text=True,
                          timeout=timeout_s, check=False)


@pytest.fixture(scope='module')
def compile_runs(install):
    """The install's check before, its compile (by the colcon workspace's console script),
    its check after, and a second compile."""
    before = _run(install, 'sphere-twin', 'compile', '--check', timeout_s=CHECK_TIMEOUT_S)
    first = _run(install, 'compile_physics', timeout_s=COMPILE_TIMEOUT_S)
    after = _run(install, 'sphere-twin', 'compile', '--check', timeout_s=CHECK_TIMEOUT_S)
    second = _run(install, 'sphere-twin', 'compile', timeout_s=CHECK_TIMEOUT_S)
    return before, first, after, second


@pytest.mark.slow
def test_a_fresh_install_is_cold_whatever_the_source_tree_holds(compile_runs):
    before = compile_runs[0]
    assert before.returncode == NOT_COMPILED_STATUS, before.stderr
    assert before.stdout.startswith('not compiled:')


@pytest.mark.slow
def test_the_compile_command_compiles_into_the_install_location(install, compile_runs):
    first = compile_runs[1]
    assert first.returncode == 0, first.stderr
    lines = first.stdout.splitlines()
    assert lines[0].startswith('compiling the physics for ')
    assert lines[-1].startswith('compiled ') and ' kernels in ' in lines[-1]
    own_cache = install.site_packages / 'sphere_sim'
    assert str(own_cache) in lines[-1]
    assert any(own_cache.rglob('__pycache__/*.nbc'))


@pytest.mark.slow
def test_after_compiling_the_detector_says_warm_and_a_second_compile_has_nothing_to_do(
        compile_runs):
    _, _, after, second = compile_runs
    assert after.returncode == 0, after.stdout + after.stderr
    assert after.stdout.startswith('compiled: all ')
    assert second.returncode == 0, second.stderr
    assert second.stdout.startswith('already compiled: all ')


@pytest.mark.ros
@pytest.mark.load_tolerant
@pytest.mark.slow
def test_a_second_start_publishes_without_compiling(install, compile_runs, ros_nodes):
    from sphere_twin.testing import TopicProbe

    assert compile_runs[1].returncode == 0, compile_runs[1].stderr
    with contextlib.closing(TopicProbe(ros_nodes.domain_id, [SURFACE_NORMAL])) as probe:
        node = ros_nodes.start(str(install.executable('simulator')),
                               parameter_args(plant='continuous'),
                               env_overrides=install.environment())
        probe.process = node
        probe.spin_until(lambda: probe.messages[SURFACE_NORMAL.name], FIRST_MESSAGE_TIMEOUT_S,
                         f'{SURFACE_NORMAL.name} from the installed simulator')
    log = node.stderr_text() + node.stdout_text()
    assert COMPILING_LINE not in log and COMPILED_LINE not in log, log
    # It ran from the install, not from the source tree.
    assert str(install.prefix) in node.command[0]


# --- the start-up benchmark's summary ------------------------------------------------------------
def test_the_startup_summary_reports_the_median_warm_start_against_the_target():
    from sphere_twin.commands.bench_startup import StartupRun, _summary, markdown

    runs = [StartupRun('cold', 70.0, True, 66.0), StartupRun('warm', 4.0, False, None),
            StartupRun('warm', 9.0, False, None), StartupRun('warm', 4.5, False, None)]
    phases = {'imports_s': 0.5, 'cache_check_s': 0.6, 'build_plant_s': 3.0}
    summary = _summary(runs, phases, (1.0, 1.0, 1.0))
    assert (summary['cold_s'], summary['cold_compile_s']) == (70.0, 66.0)
    assert summary['warm_median_s'] == 4.5
    text = markdown(summary)
    assert 'cold 70.0 s, warm 4.50 s (median of 3; target 5 s): met.' in text
    assert 'building the plant (loading the kernels, relaxing the rest pose) 3.00 s' in text
