"""Shared fixtures: an isolated ROS context per test, the repository paths."""

import pathlib

import pytest

from rrtq_bringup.testing import isolated_context

ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.fixture
def ros():
    """(context, executor, domain id) private to the test."""
    with isolated_context() as handles:
        yield handles


@pytest.fixture
def root() -> pathlib.Path:
    return ROOT
