from setuptools import find_packages, setup

package_name = 'rrtq_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='rrtq maintainers',
    maintainer_email='maintainers@rrtq.dev',
    description='Plant simulator, disturbance injector and obstacle spawner of the rrtq graph, with pure numpy cores.',
    license='MIT',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'simulator_node = rrtq_sim.simulator_node:main',
            'disturbance_node = rrtq_sim.disturbance_node:main',
            'spawner_node = rrtq_sim.spawner_node:main',
        ],
    },
)
