"""Build script for the lf_predictor_ros ament_python package.

Works for `colcon build` (plain and --symlink-install) and for `pip install` into a venv. pip
ignores setup.cfg's install_scripts, so `make venv` links the console scripts into
`<venv>/lib/lf_predictor_ros/` itself (see .ci/bootstrap.sh).
"""
from glob import glob
import os

from setuptools import find_packages, setup

PACKAGE = 'lf_predictor_ros'
HERE = os.path.dirname(os.path.abspath(__file__))

# Executables of the interface contract (shared/reference/interfaces.md). Register a name only
# when its module exists.
CONSOLE_SCRIPTS = [
    'predictor = lf_predictor_ros.nodes.predictor_node:main',
    'observer = lf_predictor_ros.nodes.observer_node:main',
    'simulator = sim_ros.nodes.simulator_node:main',
    'dp_controller = sim_ros.nodes.dp_controller_node:main',
    'recorder = lf_predictor_ros.bag.recorder_node:main',
    'replay = lf_predictor_ros.bag.replay:main',
    'play = lf_predictor_ros.bag.play:main',
    'demo = lf_predictor_ros.demo.demo:main',
    'benchmark = lf_predictor_ros.benchmark.benchmark:main',
]


def _module_exists(entry: str) -> bool:
    module = entry.split('=')[1].split(':')[0].strip()
    return os.path.exists(os.path.join(HERE, *module.split('.')) + '.py')


def _config_files() -> list[tuple[str, list[str]]]:
    """Install config/**/*.yaml under share/<pkg>/config, keeping the folder structure."""
    out: dict[str, list[str]] = {}
    for path in sorted(glob('config/**/*.yaml', root_dir=HERE, recursive=True)):
        out.setdefault(os.path.join('share', PACKAGE, os.path.dirname(path)), []).append(path)
    return sorted(out.items())


setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    package_data={PACKAGE: ['py.typed'], 'sim_ros': ['py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        *_config_files(),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='lf_predictor_ros developers',
    maintainer_email='dev@lf-predictor.invalid',
    description='Learned low-frequency pose predictor (wave filter) for ship dynamic positioning',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [e for e in CONSOLE_SCRIPTS if _module_exists(e)],
    },
)
