from setuptools import find_packages, setup

package_name = 'softkin_fk'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', ['softkin_fk/config/finger_graph.yaml']),
    ],
    package_data={package_name: ['config/*.yaml']},
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Soft robot stack developers',
    maintainer_email='dev@soft-robot-stack.invalid',
    description='Geometric forward and inverse kinematics of soft robots on tetrahedral and prism meshes',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'softkin = softkin_fk.cli:main',
            'kinematics_node = softkin_fk.nodes.kinematics_node:main',
            'stepper_driver = softkin_fk.nodes.stepper_driver:main',
            'marlin_emulator = softkin_fk.nodes.marlin_emulator:main',
            'softkin-twin = softkin_fk.twin:main',
        ],
    },
)
