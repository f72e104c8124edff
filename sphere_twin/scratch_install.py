"""Install this source tree into a scratch prefix, laid out as a colcon workspace's install.

What runs from there runs on installed copies, not on the source tree: its own site-packages
(``lib/pythonX.Y/site-packages``), its executables in ``lib/sphere_twin`` (setup.cfg), and a
numba cache of its own beside the installed kernels. The start-up benchmark and the tests of
the first start use it; colcon's ament_python build runs the same ``setup.py`` commands.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

PACKAGE_NAME = 'sphere_twin'
INSTALL_TIMEOUT_S = 300.0


class InstallError(RuntimeError):
    """The scratch install failed (its output's last lines are in the message)."""


@dataclasses.dataclass(frozen=True)
class ScratchInstall:
    """An install prefix made by :func:`install_into`."""

    prefix: Path

    @property
    def site_packages(self) -> Path:
        # setuptools' layout under an install prefix on POSIX, which colcon uses too.
        return Path(sysconfig.get_path('purelib', 'posix_prefix', vars={'base': str(self.prefix)}))

    def executable(self, name: str) -> Path:
        """A console script of the package (``simulator``, ``sphere-twin``)."""
        return self.prefix / 'lib' / PACKAGE_NAME / name

    def environment(self) -> dict[str, str]:
        """Variables (on top of the caller's) that make a child run from this install, as
        sourcing a colcon workspace does: its site-packages first on the path and its prefix
        in the ament index; and numba's cache beside the installed kernels (an empty
        NUMBA_CACHE_DIR is numba's unset: a directory set for the caller would be shared by
        every install, not this one's own)."""
        path = [str(self.site_packages), *filter(None, [os.environ.get('PYTHONPATH')])]
        return {'PYTHONPATH': os.pathsep.join(path), 'NUMBA_CACHE_DIR': '',
                'AMENT_PREFIX_PATH': os.pathsep.join(
                    [str(self.prefix), *filter(None, [os.environ.get('AMENT_PREFIX_PATH')])])}


def source_root() -> Path:
    """The source tree this package was imported from (the one with ``setup.py``).

    Raises
    ------
    InstallError
        When the package runs from an install, not from its source tree.
    """
    root = Path(__file__).resolve().parents[1]
    if not (root / 'setup.py').is_file():
        raise InstallError(f'{root} is an install, not the source tree (no setup.py): run this '
                           'from the source tree')
    return root


def install_into(prefix: Path, source: Path | None = None) -> ScratchInstall:
    """Install ``source`` (this source tree by default) into ``prefix`` as colcon does.

    The build's scratch files go to ``prefix/.build``, not into the source tree (someone may
    be building from it at the same time).
    """
    source = source_root() if source is None else source
    prefix = Path(prefix).resolve()
    build = prefix / '.build'
    build.mkdir(parents=True, exist_ok=True)
    # colcon's ament_python build: egg_info, build and an externally managed install, each
    # with its scratch directory outside the source tree.
    command = [sys.executable, 'setup.py', '--quiet', 'egg_info', '--egg-base', str(build),
               'build', '--build-base', str(build / 'build'), 'install', '--prefix', str(prefix),
               '--record', str(build / 'install.log'), '--single-version-externally-managed']
    try:
        result = subprocess.run(command, cwd=source, capture_output=True, text=True,
                                timeout=INSTALL_TIMEOUT_S, check=False)
    except subprocess.TimeoutExpired:
        raise InstallError(f'setup.py install took over {INSTALL_TIMEOUT_S:g} s') from None
    if result.returncode != 0:
        tail = ' | '.join((result.stderr or result.stdout).strip().splitlines()[-3:])
        raise InstallError(f'setup.py install into {prefix} failed: {tail}')
    install = ScratchInstall(prefix)
    if not (install.site_packages / 'sphere_sim').is_dir():
        raise InstallError(f'setup.py install put no sphere_sim into {install.site_packages}')
    return install
