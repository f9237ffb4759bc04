# Copyright 2026 umbrella_sim developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

from glob import glob
import os
import shutil

from setuptools import Extension, find_packages, setup
from setuptools.command.build_ext import build_ext

NO_COMPILER = (
    'umbrella_sim needs a C compiler: the physics step is compiled code '
    '(umbrella_sim/core/_kernel.c, plain C99 + libm). Install one (Debian/Ubuntu: '
    '`sudo apt-get install gcc`, or build-essential) and run the installation again.')


#: the compiled step: a plain shared library (no Python module init), loaded with ctypes by
#: umbrella_sim/core/kernel.py from exactly this file, with its interface in _kernel.h
KERNEL = 'umbrella_sim.core.libumbrella_kernel'


class BuildKernel(build_ext):
    """Build the compiled step; without a working C compiler, stop with one clear message."""

    def get_ext_filename(self, fullname):
        # libumbrella_kernel.so, not a CPython-tagged extension module's name (asked for by
        # the full name, and by its last part alone: build_ext.get_ext_fullpath)
        if fullname in (KERNEL, KERNEL.rpartition('.')[2]):
            return os.path.join(*fullname.split('.')) + '.so'
        return super().get_ext_filename(fullname)

    def get_export_symbols(self, ext):
        # no PyInit_*: the library exports the API its header marks (-fvisibility=hidden)
        if ext.name == KERNEL:
            return []
        return super().get_export_symbols(ext)

    def run(self):
        try:
            super().run()
        except Exception as exc:  # distutils raises several types for a missing compiler
            raise SystemExit(f'error: {NO_COMPILER}\n({type(exc).__name__}: {exc})') from None

    def build_extension(self, ext):
        try:
            super().build_extension(ext)
        except Exception as exc:
            cc = getattr(self.compiler, 'compiler', None) or ['']
            if shutil.which(cc[0]):       # a compiler that ran and failed: not a missing one
                raise SystemExit(f'error: the compiled step {ext.sources} did not build with '
                                 f'{cc[0]}: see its messages above ({type(exc).__name__}: '
                                 f'{exc})') from None
            raise SystemExit(f'error: {NO_COMPILER}\n({type(exc).__name__}: {exc})') from None


package_name = 'umbrella_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['tests', 'tests.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.json')
         + glob('config/*.xml')),
        ('share/' + package_name + '/config/sweeps', glob('config/sweeps/*.yaml')),
        ('share/' + package_name + '/msg_docs', glob('msg_docs/*.md')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/urdf', glob('urdf/*.urdf')),
        ('share/' + package_name + '/rviz', glob('rviz/*.rviz')),
    ],
    # the interface of the compiled step: kernel.py reads it at import
    package_data={'umbrella_sim.core': ['_kernel.h']},
    # the compiled integrator (plain C, loaded with ctypes): required
    ext_modules=[Extension(KERNEL,
                           ['umbrella_sim/core/_kernel.c',
                            'umbrella_sim/core/_kernel_nonlinear.c',
                            'umbrella_sim/core/_kernel3d.c'],
                           depends=['umbrella_sim/core/_kernel.h',
                                    'umbrella_sim/core/_kernel_elastic.h',
                                    'umbrella_sim/core/_kernel_dense.h',
                                    'umbrella_sim/core/_kernel_crest.h',
                                    'umbrella_sim/core/_kernel3d_nonlinear.h',
                                    'umbrella_sim/core/_kernel3d_base.h',
                                    'umbrella_sim/core/_kernel3d_figures.h',
                                    'umbrella_sim/core/_kernel3d_damping.h'],
                           extra_compile_args=['-O3', '-std=c99', '-fvisibility=hidden'],
                           libraries=['m'])],
    cmdclass={'build_ext': BuildKernel},
    # every import (tests/test_package_metadata.py); the ROS packages are package.xml's
    install_requires=['setuptools', 'numpy', 'scipy', 'PyYAML', 'mcap', 'zstandard',
                      'matplotlib', 'dask', 'distributed', 'pyarrow'],
    # the ROS 2 packages are package.xml's (a ROS 2 install has them); in a plain venv from
    # PyPI: pip install 'umbrella_sim[ros]' (the wheels requirements.txt names)
    extras_require={'test': ['pytest'],     # (tests_require: gone from setuptools)
                    'ros': ['ros-jazzy-rclpy', 'ros-jazzy-common-interfaces',
                            'ros-jazzy-rmw-fastrtps-cpp']},
    zip_safe=False,      # a shared library, loaded from its file
    maintainer='umbrella_sim developers',
    maintainer_email='dev@umbrella-sim.invalid',
    description='Real-time flexible umbrella-frame deployment simulator (ROS 2 Jazzy)',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            # `ros2 run umbrella_sim <name>`: one naming style, snake_case as ROS executables
            'umbrella_node = umbrella_sim.tools.entry:node_main',
            # (each takes SIGINT/SIGTERM before its heavy imports: stop_signals.py)
            'umbrella_sim = umbrella_sim.tools.entry:cli_main',
            'umbrella_replay = umbrella_sim.tools.entry:replay_main',
            'umbrella_compare = umbrella_sim.tools.entry:compare_main',
            # the earlier names, kept as aliases
            'umbrella-sim = umbrella_sim.tools.entry:cli_main',
            'umbrella-replay = umbrella_sim.tools.entry:replay_main',
            'umbrella-compare = umbrella_sim.tools.entry:compare_main',
            'deploy_controller = umbrella_sim.tools.entry:controller_main',
        ],
    },
)
