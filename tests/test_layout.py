"""The suite covers every package: each package's test directory is a pytest test path."""

from __future__ import annotations

import configparser
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_every_package_test_directory_is_collected():
    config = configparser.ConfigParser()
    config.read(ROOT / 'pytest.ini')
    paths = {ROOT / p for p in config['pytest']['testpaths'].split()}
    for test_dir in sorted((ROOT / 'ros2_ws' / 'src').glob('*/test')):
        if any(test_dir.glob('test_*.py')):
            assert test_dir in paths, f'{test_dir.relative_to(ROOT)} is not in pytest.ini testpaths'
