from setuptools import find_packages, setup

package_name = 'frog_bridge'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Soft robot stack developers',
    maintainer_email='dev@soft-robot-stack.invalid',
    description='Serial link (UART to the nRF52 BLE relay) to the frog robot, limb protection, and a robot emulator',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'bridge_node = frog_bridge.nodes.bridge_node:main',
            'robot_emulator = frog_bridge.nodes.robot_emulator:main',
            'frog-bridge = frog_bridge.cli:main',
        ],
    },
)
