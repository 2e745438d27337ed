from glob import glob

from setuptools import find_packages, setup

package_name = 'hcloth_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/rviz', glob('rviz/*.rviz')),
    ],
    # the pip-installable imports; the ROS 2 ones (rclpy, messages, launch) are in
    # package.xml: rosdep installs those (test/test_dependencies.py keeps both complete)
    install_requires=['setuptools', 'numpy', 'numba', 'pyyaml', 'matplotlib', 'tqdm',
                      'rerun-sdk==0.41.0', 'mcap'],
    zip_safe=True,
    maintainer='hcloth_ros maintainers',
    maintainer_email='maintainers@hcloth-ros.dev',
    description='Real-time mass-spring cloth simulation for ROS 2 on a level hierarchy '
                '(BDF2 with multigrid-preconditioned CG, or the hierarchical method).',
    license='Apache-2.0',
    extras_require={
        'test': ['pytest'],
        # other simulators the benchmark compares against (hcloth_bench, section peers)
        'peers': ['mujoco==3.14.0', 'pybullet==3.2.7', 'newton==1.8.0', 'warp-lang==1.19.0'],
    },
    entry_points={
        'console_scripts': [
            'sim_node = hcloth_ros.start:main',
            'hcloth_demo = hcloth_ros.demo.headless:main',
            'hcloth_demo_run = hcloth_ros.demo.run:main',
            'hcloth_fold_client = hcloth_ros.demo.fold_client:main',
            'hcloth_node_bench = hcloth_ros.bench.node:main',
            'hcloth_engine_bench = hcloth_ros.bench.engine:main',
            'hcloth_bench = hcloth_ros.bench.__main__:main',
            'hcloth_contact_bench = hcloth_ros.bench.self_contact:main',
            'hcloth_stress = hcloth_ros.bench.stress:main',
            'hcloth_soak = hcloth_ros.bench.soak:main',
            'hcloth_replay = hcloth_ros.replay:main',
        ],
    },
)
