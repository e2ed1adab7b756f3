"""Point the ROS wheels' CMake exports at this interpreter (docs/design.md, Setup, quirk 1)."""
import pathlib
import sys
import sysconfig

import numpy

BUILDER_PATHS = {
    '/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include': numpy.get_include(),
    '/opt/python/cp311-cp311/include/python3.11': sysconfig.get_paths()['include'],
}


def main(prefix: str) -> int:
    changed = 0
    for path in pathlib.Path(prefix, 'share').rglob('*.cmake'):
        text = path.read_text()
        fixed = text
        for old, new in BUILDER_PATHS.items():
            fixed = fixed.replace(old, new)
        if fixed != text:
            path.write_text(fixed)
            changed += 1
    print(f'[setup] fixed {changed} CMake files', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1]))
