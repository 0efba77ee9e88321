from setuptools import find_packages, setup

package_name = 'frog_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    # the shipped eq. 9 fit (frog_sim/data/actuation_fit.json): needed at run time
    package_data={package_name: ['data/*.json']},
    include_package_data=True,
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Soft robot stack developers',
    maintainer_email='dev@soft-robot-stack.invalid',
    description='2D discrete-elastic-rods simulator of the frog-inspired swimming soft robot',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'sim_node = frog_sim.nodes.sim_node:main',
            'rollout_node = frog_sim.nodes.rollout_node:main',
            'frog-library = frog_sim.library_cli:main',
            'frog-sweep = frog_sim.sweep_cli:main',
            'frog-sim = frog_sim.cli:main',
        ],
    },
)
