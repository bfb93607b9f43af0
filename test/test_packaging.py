"""Issue 2: the package installs the way `ros2 run` expects, via colcon and via the venv.

`ros2 run PKG EXE` (ros2cli) finds PKG's prefix through the ament index marker
`share/ament_index/resource_index/packages/PKG` on AMENT_PREFIX_PATH and then runs
`<prefix>/lib/PKG/EXE`. ros2cli is not on PyPI, so `_ros2_run_path` below does that lookup with
`ament_index_python`, exactly as ros2cli's `get_executable_path` does.
"""
from __future__ import annotations

import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parents[1]
PKG = 'lf_predictor_ros'


def _registered_executables() -> list[str]:
    """Console-script names setup.py registers (only those whose module exists)."""
    out = subprocess.run(
        [sys.executable, '-c',
         'import runpy, setuptools, sys\n'
         'captured = {}\n'
         'setuptools.setup = lambda **kw: captured.update(kw)\n'
         'runpy.run_path("setup.py")\n'
         'print("\\n".join(e.split("=")[0].strip() for e in '
         'captured["entry_points"]["console_scripts"]))'],
        cwd=REPO, capture_output=True, text=True, check=True)
    return [line for line in out.stdout.split() if line]


def test_setup_registers_only_existing_executables() -> None:
    names = _registered_executables()
    assert names, 'setup.py registers no executable at all'
    expected = {'predictor', 'observer', 'simulator', 'dp_controller', 'recorder', 'replay',
                'play', 'demo', 'benchmark'}
    assert set(names) <= expected, f'unexpected executables: {set(names) - expected}'


def _ros2_run_path(executable: str, env: dict[str, str]) -> Path:
    code = ('from ament_index_python.packages import get_package_prefix\n'
            f'print(get_package_prefix("{PKG}"))')
    prefix = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                            text=True, check=True).stdout.strip()
    return Path(prefix) / 'lib' / PKG / executable


def _check_layout(prefix: Path, env: dict[str, str]) -> None:
    marker = prefix / 'share/ament_index/resource_index/packages' / PKG
    assert marker.is_file(), f'ament index marker missing: {marker}'
    assert (prefix / 'share' / PKG / 'package.xml').is_file()
    executables = _registered_executables()
    for name in executables:
        path = _ros2_run_path(name, env)
        assert path.parent == prefix / 'lib' / PKG
        assert path.exists() and os.access(path, os.X_OK), f'{path} is not an executable'
    # Every executable answers --help without starting ROS; check one fully (each costs ~1 s).
    probe = _ros2_run_path(executables[0], env)
    result = subprocess.run([str(probe), '--help'], env=env, capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, result.stderr
    assert 'usage' in result.stdout.lower()


@pytest.mark.slow
@pytest.mark.parametrize('symlink', [False, True], ids=['plain', 'symlink-install'])
def test_colcon_build_gives_ros2_run_layout(tmp_path: Path, symlink: bool) -> None:
    colcon = shutil.which('colcon')
    assert colcon, 'colcon is not installed in the venv (make venv installs it)'
    args = [colcon, 'build', '--base-paths', str(REPO), '--build-base', str(tmp_path / 'build'),
            '--install-base', str(tmp_path / 'install')]
    if symlink:
        args.append('--symlink-install')
    subprocess.run(args, cwd=tmp_path, check=True, capture_output=True, timeout=300)
    prefix = tmp_path / 'install' / PKG
    env = dict(os.environ)
    env['AMENT_PREFIX_PATH'] = f'{prefix}:{env.get("AMENT_PREFIX_PATH", "")}'
    site = next((prefix / 'lib').glob('python3*/site-packages'))
    env['PYTHONPATH'] = f'{site}:{env.get("PYTHONPATH", "")}'
    _check_layout(prefix, env)
    if not symlink:
        # A plain build installs a copy of the sources, not a link back to the repo.
        assert (site / PKG / 'core').is_dir()
    # config/**/*.yaml is installed under share/<pkg>/config.
    share = prefix / 'share' / PKG
    repo_yaml = sorted(p.relative_to(REPO) for p in (REPO / 'config').rglob('*.yaml'))
    assert repo_yaml, 'config/ has no YAML files'
    for rel in repo_yaml:
        assert (share / rel).is_file(), f'{rel} not installed'


def test_venv_gives_ros2_run_layout() -> None:
    prefix = Path(sys.prefix)
    assert prefix != Path(sys.base_prefix), 'tests must run inside the project venv'
    env = dict(os.environ)
    assert str(prefix) in env.get('AMENT_PREFIX_PATH', '').split(':'), (
        'AMENT_PREFIX_PATH does not contain the venv: source .venv/setup.bash')
    _check_layout(prefix, env)
    # ...and as a plain command on the venv's PATH.
    for name in _registered_executables():
        assert shutil.which(name) == str(prefix / 'bin' / name)


def test_readme_parameter_table_shows_the_shipped_defaults() -> None:
    """Every PredictorParams field is in the README table with its current default."""
    import dataclasses
    import re

    from lf_predictor_ros.core.params import PredictorParams

    readme = (REPO / 'README.md').read_text(encoding='utf-8')
    rows = dict(re.findall(r'^\| `(\w+)` \| ([^|]+) \|', readme, flags=re.MULTILINE))
    defaults = PredictorParams()
    for field in dataclasses.fields(PredictorParams):
        value = getattr(defaults, field.name)
        if isinstance(value, bool):
            shown = 'true' if value else 'false'
        elif isinstance(value, tuple):
            shown = '[' + ', '.join(str(v) for v in value) + ']'
        else:
            shown = str(value)
        assert rows.get(field.name, '').strip() == shown, field.name
