"""Polygon geometry (checked against shapely) and the Otte file parser."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from rrtq_common.geometry import (
    disc_intersects_polygon,
    point_in_polygon,
    point_polygon_distance,
    polygon_from_circle,
)
from rrtq_common.otte import load_otte
from rrtq_testing.paths import OTTE

PEER = OTTE
SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
# Concave "L", clockwise, to exercise both orientation and concavity.
ELL = np.array([[0.0, 0.0], [0.0, 3.0], [1.0, 3.0], [1.0, 1.0], [3.0, 1.0], [3.0, 0.0]])


def test_circle_polygon_contains_the_circle_and_is_tangent():
    center, radius = np.array([3.0, -1.0]), 1.5
    poly = polygon_from_circle(center, radius, 16)
    assert poly.shape == (16, 2)
    angles = np.linspace(0.0, 2.0 * np.pi, 721)
    rim = center + radius * np.column_stack((np.cos(angles), np.sin(angles)))
    assert np.all(point_polygon_distance(rim, poly) == 0.0)  # the whole circle is inside
    # Tight: edges are tangent, so the boundary's closest approach to the centre is r.
    assert shapely.Polygon(poly).exterior.distance(shapely.Point(center)) == pytest.approx(radius)
    assert shapely.Polygon(poly).area > 0.0  # counter-clockwise


def test_point_in_polygon_concave_both_orientations():
    pts = np.array([[0.5, 2.0], [2.0, 0.5], [2.0, 2.0], [-0.1, 0.5], [0.5, 0.5]])
    expected = [True, True, False, False, True]
    np.testing.assert_array_equal(point_in_polygon(pts, ELL), expected)
    np.testing.assert_array_equal(point_in_polygon(pts, ELL[::-1]), expected)
    assert point_in_polygon([1.0, 1.0], SQUARE).shape == ()


def test_distance_matches_shapely_on_random_points():
    rng = np.random.default_rng(5)
    pts = rng.uniform(-3.0, 6.0, size=(500, 2))
    for poly in (SQUARE, ELL, polygon_from_circle([1.0, 1.0], 2.0, 7)):
        shape = shapely.Polygon(poly)
        expected = np.array([shape.distance(shapely.Point(p)) for p in pts])
        np.testing.assert_allclose(point_polygon_distance(pts, poly), expected, atol=1e-12)
    assert point_polygon_distance(np.zeros((0, 2)), SQUARE).shape == (0,)
    assert point_polygon_distance([5.0, 2.0], SQUARE) == pytest.approx(3.0)


def test_disc_intersection_cases():
    assert disc_intersects_polygon([3.0, 1.0], 1.0, SQUARE)  # touching an edge
    assert not disc_intersects_polygon([3.0, 1.0], 0.99, SQUARE)
    assert disc_intersects_polygon([1.0, 1.0], 0.1, SQUARE)  # disc inside
    assert disc_intersects_polygon([1.0, 1.0], 50.0, SQUARE)  # polygon inside
    corner = 2.0 + 1.0 / math.sqrt(2.0)
    assert disc_intersects_polygon([corner, corner], 1.0 + 1e-9, SQUARE)
    assert not disc_intersects_polygon([corner, corner], 1.0 - 1e-9, SQUARE)


def test_load_bneck_without_flags():
    polys = load_otte(PEER / 'BNeck.txt')
    assert len(polys) == 3
    assert all(flag is None for _, flag in polys)
    assert all(p.shape == (4, 2) for p, _ in polys)  # closing vertex dropped
    np.testing.assert_array_equal(polys[2][0], [[1.0, 0.1], [1.0, -0.1], [-1.0, -0.1], [-1.0, 0.1]])


def test_load_rand_static_with_flags():
    polys = load_otte(PEER / 'rand_Static.txt')
    assert len(polys) == 35
    assert all(flag == 0 for _, flag in polys)
    assert all(p.shape == (4, 2) for p, _ in polys)
    np.testing.assert_allclose(polys[0][0][0], [-11.278802, -35.219298])
    assert np.all(np.abs(np.concatenate([p for p, _ in polys])) <= 50.0)


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / 'env.txt'
    path.write_text(text)
    return path


def test_mixed_flags_and_whitespace_separated_vertices(tmp_path):
    text = '2\n3\n0 0\n1 0\n0 1\n-1\n\n3\n5, 5\n6, 5\n5, 6\n1\n'
    polys = load_otte(write(tmp_path, text))
    assert [flag for _, flag in polys] == [-1, 1]
    assert polys[1][0].shape == (3, 2)


def test_single_polygon_with_and_without_flag(tmp_path):
    assert load_otte(write(tmp_path, '1\n3\n0,0\n1,0\n0,1\n'))[0][1] is None
    assert load_otte(write(tmp_path, '1\n3\n0,0\n1,0\n0,1\n0\n'))[0][1] == 0


@pytest.mark.parametrize(
    ('text', 'line', 'what'),
    [
        ('2\n3\n0,0\n1,0\nx,1\n', 5, 'vertex'),
        ('1\n3\n0,0\n1,0\n', 5, 'end of file'),
        ('1\n2\n0,0\n1,0\n', 2, 'at least 3'),
        ('2\n3\n0,0\n1,0\n0,1\n0\n3\n0,0\n1,0\n0,1\n7\n', 11, 'flag'),
        ('1\n3\n0,0\n1,0\n0,1\n0\nextra\n', 7, 'unexpected content'),
        ('one\n', 1, 'number of polygons'),
        ('1\n3\n0,0\n1,1\n2,2\n', 2, 'zero area'),
    ],
)
def test_malformed_files_name_the_line(tmp_path, text, line, what):
    path = write(tmp_path, text)
    with pytest.raises(ValueError, match=what) as info:
        load_otte(path)
    assert f'{path}:{line}:' in str(info.value)
