"""
Every import of the package is declared, and every declaration is used.

``rosdep install`` reads package.xml and ``pip install`` reads setup.py: an import missing
from them works here (the venv has everything) and fails on a user's machine. The
imports are read from the source (every ``import``, at any depth), so a lazy import
counts too.
"""

import ast
import os
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# import name -> (rosdep key, pip requirement or None for ROS packages rosdep installs)
KEYS = {
    'ament_index_python': ('ament_index_python', None),
    'builtin_interfaces': ('builtin_interfaces', None),
    'diagnostic_msgs': ('diagnostic_msgs', None),
    'geometry_msgs': ('geometry_msgs', None),
    'launch': ('launch', None),
    'launch_ros': ('launch_ros', None),
    'rcl_interfaces': ('rcl_interfaces', None),
    'rclpy': ('rclpy', None),
    'rosgraph_msgs': ('rosgraph_msgs', None),
    'sensor_msgs': ('sensor_msgs', None),
    'std_msgs': ('std_msgs', None),
    'std_srvs': ('std_srvs', None),
    'visualization_msgs': ('visualization_msgs', None),
    'matplotlib': ('python3-matplotlib', 'matplotlib'),
    'numba': ('python3-numba', 'numba'),
    'llvmlite': ('python3-numba', 'numba'),     # numba's own compiler, installed with it
    'numpy': ('python3-numpy', 'numpy'),
    'tqdm': ('python3-tqdm', 'tqdm'),
    'yaml': ('python3-yaml', 'pyyaml'),
    'mcap': ('mcap-ros2-support', 'mcap'),
    'mcap_ros2': ('mcap-ros2-support', 'mcap-ros2-support'),
    'rerun': ('python3-rerun-sdk-pip', 'rerun-sdk'),
}


def _sources():
    for folder in ('hcloth_ros', 'launch'):
        for base, _, files in os.walk(os.path.join(ROOT, folder)):
            yield from (os.path.join(base, f) for f in files if f.endswith('.py'))


def imported():
    """Return the top-level names of third-party modules the package imports."""
    names = set()
    for path in _sources():
        with open(path) as f:
            tree = ast.parse(f.read(), path)
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names.update(alias.name.split('.')[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names.add(node.module.split('.')[0])
    return {n for n in names if n not in sys.stdlib_module_names and n != 'hcloth_ros'}


def package_xml_keys(tag):
    root = ElementTree.parse(os.path.join(ROOT, 'package.xml')).getroot()
    return {e.text.strip() for e in root.iter(tag)}


def install_requires():
    """Return setup.py's ``install_requires`` names (read from its source, not run)."""
    with open(os.path.join(ROOT, 'setup.py')) as f:
        tree = ast.parse(f.read())
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == 'install_requires':
            return {r.split('=')[0].split('>')[0].split('<')[0].strip()
                    for r in ast.literal_eval(node.value)}
    raise AssertionError('setup.py has no install_requires')


def test_every_import_has_a_known_key():
    assert imported() - set(KEYS) == set(), 'add the new imports to KEYS and declare them'


# run, not imported: the executables the launch file starts besides the node
LAUNCHED = {'rviz2'}


def test_package_xml_declares_exactly_what_is_imported_or_launched():
    wanted = {KEYS[name][0] for name in imported()} | LAUNCHED
    assert package_xml_keys('exec_depend') == wanted
    with open(os.path.join(ROOT, 'launch', 'sim.launch.py')) as f:
        launch = f.read()
    assert all(f"executable='{exe}'" in launch for exe in LAUNCHED)


def test_setup_py_requires_every_pip_import():
    wanted = {KEYS[name][1] for name in imported() if KEYS[name][1]}
    assert install_requires() - {'setuptools'} == wanted


def test_the_pip_key_rosdep_lacks_is_defined_in_the_repository():
    with open(os.path.join(ROOT, 'rosdep.yaml')) as f:
        keys = yaml.safe_load(f)
    pip = {KEYS[name][0] for name in imported() if KEYS[name][0].endswith('-pip')}
    assert pip <= set(keys)
    assert keys['python3-rerun-sdk-pip']['ubuntu']['pip']['packages'] == ['rerun-sdk==0.41.0']


def test_the_node_imports_no_recording_library_until_it_records():
    code = ('import sys, hcloth_ros.node; '
            'print(sorted(m for m in ("rerun", "mcap", "mcap_ros2", "matplotlib", "tqdm") '
            'if m in sys.modules))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == '[]'
