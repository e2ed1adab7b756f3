"""PolygonSet: signed distances, nearest and disc queries against shapely, brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from rrtq_common.geometry import polygon_from_circle
from rrtq_common.polygon_set import LivePolygons, PolygonSet

ELL = np.array([[0.0, 0.0], [0.0, 3.0], [1.0, 3.0], [1.0, 1.0], [3.0, 1.0], [3.0, 0.0]])


def shapely_signed(point, poly) -> float:
    shape, p = shapely.Polygon(poly), shapely.Point(point)
    return -shape.exterior.distance(p) if shape.contains(p) else shape.distance(p)


def random_scene(rng, count=60):
    polys = [polygon_from_circle(rng.uniform(-20, 20, 2), rng.uniform(0.3, 2.0),
                                 int(rng.integers(3, 33))) for _ in range(count)]
    return polys + [ELL + rng.uniform(-20, 20, 2) for _ in range(5)]


def test_signed_distance_matches_shapely_inside_outside_and_concave():
    rng = np.random.default_rng(1)
    polys = random_scene(rng)
    pset = PolygonSet(polys)
    for point in rng.uniform(-22, 22, (200, 2)):
        got = pset.signed_distances(point, np.arange(len(polys)))
        want = [shapely_signed(point, p) for p in polys]
        np.testing.assert_allclose(got, want, atol=1e-9)
    # Order of the answer follows the order asked; the L's notch is outside.
    got = PolygonSet([ELL, ELL + 10]).signed_distances([2.0, 2.0], [1, 0])
    np.testing.assert_allclose(got, [shapely_signed([2, 2], ELL + 10), 1.0])
    assert PolygonSet([ELL]).signed_distances([0.5, 0.5], [0])[0] == pytest.approx(-0.5)
    assert PolygonSet([ELL]).signed_distances([1.0, 2.0], [0])[0] == 0.0  # on the boundary


def test_nearest_is_the_brute_force_minimum():
    rng = np.random.default_rng(2)
    polys = random_scene(rng)
    pset = PolygonSet(polys)
    for point in rng.uniform(-22, 22, (300, 2)):
        want = [shapely_signed(point, p) for p in polys]
        value, index = pset.nearest(point)
        assert value == pytest.approx(min(want), abs=1e-9)
        assert want[index] == pytest.approx(value, abs=1e-9)
    # Inside two overlapping polygons the deeper one is the nearest (most negative).
    small, big = polygon_from_circle([0, 0], 1.0), polygon_from_circle([0.5, 0], 3.0)
    value, index = PolygonSet([small, big]).nearest([0.2, 0.0])
    assert index == 1 and value < -2.0


def test_nearest_and_within_on_an_empty_set():
    assert PolygonSet([]).nearest([0, 0]) == (math.inf, -1)
    assert PolygonSet([]).within([0, 0], 5.0).size == 0


def test_within_is_the_set_of_polygons_meeting_the_closed_disc():
    rng = np.random.default_rng(3)
    polys = random_scene(rng)
    pset = PolygonSet(polys)
    for point in rng.uniform(-22, 22, (100, 2)):
        want = [i for i, p in enumerate(polys)
                if shapely.Polygon(p).distance(shapely.Point(point)) <= 4.0]
        assert pset.within(point, 4.0).tolist() == want
    with pytest.raises(ValueError):
        PolygonSet([ELL[:2]])


def test_small_sets_answer_as_the_pruned_search_bit_for_bit(monkeypatch):
    # Up to PolygonSet.SMALL polygons every one is tested; the answers (values to the last
    # bit, indices) are those of the search that prunes by bounding box, and shapely's.
    rng = np.random.default_rng(4)
    scenes = [random_scene(rng, count)[-count - 1:] for count in (0, 1, 3, 8, 11)]
    points = rng.uniform(-22, 22, (150, 2))
    assert all(len(s) <= PolygonSet.SMALL for s in scenes)
    answers = []
    for small in (PolygonSet.SMALL, 0):
        monkeypatch.setattr(PolygonSet, 'SMALL', small)
        answers.append([(pset.nearest(p), pset.within(p, 4.0).tolist(),
                         pset.signed_distances(p, np.arange(len(pset))).tobytes(),
                         pset.signed_distances(p, np.arange(len(pset))[::-1]).tobytes())
                        for pset in map(PolygonSet, scenes) for p in points])
    assert answers[0] == answers[1]
    for point, ((value, index), *_) in zip(points, answers[0][-len(points):]):
        want = [shapely_signed(point, poly) for poly in scenes[-1]]
        assert value == pytest.approx(min(want), abs=1e-9)
        assert want[index] == pytest.approx(value, abs=1e-9)


class Item:
    def __init__(self, polygon):
        self.polygon = polygon


def test_live_polygons_rebuild_only_when_the_items_change():
    a, b = Item(ELL), Item(ELL + 10)
    live = LivePolygons()
    first = live.update((a, b))
    assert live.update([a, b]) is first                     # same items, new sequence
    assert live.update((b,)) is not first
    assert live.update((b,)).nearest([10.5, 10.5]) == (pytest.approx(-0.5), 0)
    assert live.update((Item(ELL + 10),)) is not live.update((b,))   # identity, not value
    assert len(live.update(())) == 0


def test_cast_finds_the_first_boundary_along_the_ray_as_shapely_does():
    rng = np.random.default_rng(4)
    polys = random_scene(rng)
    pset = PolygonSet(polys)
    union = shapely.union_all([shapely.Polygon(p).exterior for p in polys])
    hits = 0
    for origin in rng.uniform(-22, 22, (200, 2)):
        angle = rng.uniform(0.0, 2.0 * math.pi)
        d = np.array([math.cos(angle), math.sin(angle)])
        length = float(rng.uniform(1.0, 15.0))
        t, index, normal = pset.cast(origin, d, length)
        meet = shapely.LineString([origin, origin + length * d]).intersection(union)
        if meet.is_empty:
            assert (t, index, normal) == (math.inf, -1, (0.0, 0.0))
            continue
        hits += 1
        want = shapely.Point(origin).distance(meet)      # the nearest crossing along the ray
        assert t == pytest.approx(want, abs=1e-9)
        point = origin + t * d
        assert shapely.Polygon(polys[index]).exterior.distance(shapely.Point(point)) < 1e-9
        n = np.array(normal)
        assert n @ n == pytest.approx(1.0) and n @ d <= 0.0   # faces the way the ray came
    assert hits > 50
    # Head-on at a face of the L: its normal is the face's outward normal, -x.
    t, index, normal = PolygonSet([ELL + [5.0, 0.0]]).cast([0.0, 0.5], [2.0, 0.0], 10.0)
    assert (t, index) == (pytest.approx(5.0), 0) and normal == pytest.approx((-1.0, 0.0))
    assert PolygonSet([ELL]).cast([5.0, 0.5], [1.0, 0.0], 10.0)[1] == -1   # pointing away
    assert PolygonSet([ELL]).cast([5.0, 0.5], [-1.0, 0.0], 1.0)[1] == -1   # beyond its length
    assert PolygonSet([]).cast([0, 0], [1, 0], 5.0)[1] == -1
