from setuptools import find_packages, setup

package_name = 'rrtq_testing'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed', 'data/otte/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='rrtq maintainers',
    maintainer_email='maintainers@rrtq.dev',
    description='Ground truth for the rrtq tests and benchmarks, independent of the code '
                'under test.',
    license='MIT',
)
