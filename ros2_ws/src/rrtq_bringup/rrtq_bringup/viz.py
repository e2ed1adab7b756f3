"""What the visualisation node draws, as plain data (no rclpy, no message imports).

Foxglove's 3D panel draws ``visualization_msgs/Marker`` natively; this module decides the
markers' namespaces, colours and shapes, and which markers to delete when an obstacle
leaves a set. ``viz_node`` turns these into messages. Obstacle sets arrive whole (an
``ObstacleArray`` is never a delta), so a :class:`MarkerLayer` compares each set with the
one before: every obstacle present gets an ADD under a stable integer id, every obstacle
gone a DELETE of its id.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Iterable, Sequence

import numpy as np
import shapely

from rrtq_common.settings import like, setting
from rrtq_common.world import World

RGBA = tuple[float, float, float, float]


class Shape(enum.Enum):
    """How an obstacle set is drawn."""

    FILL = 'fill'          # TRIANGLE_LIST: the polygon's area
    OUTLINE = 'outline'    # LINE_STRIP: the closed boundary


@dataclasses.dataclass(frozen=True)
class LayerStyle:
    """One marker namespace: its name, colour, shape and height above the ground."""

    ns: str
    color: RGBA
    shape: Shape
    z: float = 0.0          # m; keeps the layers from z-fighting in the 3D panel
    width: float = 0.0      # m; line width of an outline


# The report's colours (rrtq report's map.png): grey truth, red detected, orange augmented.
TRUTH = LayerStyle('truth', (0.35, 0.35, 0.35, 0.85), Shape.FILL, z=0.0)
DETECTED = LayerStyle('detected', (0.84, 0.15, 0.16, 1.0), Shape.OUTLINE, z=0.02, width=0.08)
AUGMENTED = LayerStyle('augmented', (1.0, 0.50, 0.05, 1.0), Shape.OUTLINE, z=0.04, width=0.05)
ROBOT_COLOR: RGBA = (0.12, 0.47, 0.71, 1.0)
PERCEPTION_COLOR: RGBA = (0.12, 0.47, 0.71, 0.12)
LEG_TARGETS_COLOR: RGBA = (0.1, 0.1, 0.1, 1.0)
CURRENT_TARGET_COLOR: RGBA = (0.58, 0.0, 0.83, 1.0)
ROBOT_NS, PERCEPTION_NS = 'robot', 'perception'
LEG_TARGETS_NS, CURRENT_TARGET_NS = 'leg_targets', 'current_target'


@dataclasses.dataclass(frozen=True)
class VizConfig:
    """The visualisation node's settings (from the scenario)."""

    robot_radius: float = like(World, 'robot_radius')
    perception_radius: float = like(World, 'perception_radius')


LIVE_HOST = '127.0.0.1'
"""The live view (``rrtq run --live``) listens on loopback only."""


@dataclasses.dataclass(frozen=True)
class LiveConfig:
    """The live view's settings (``rrtq_bringup.live_node``)."""

    port: int = setting(8765, low=1, high=65535,
                        doc='TCP port of the Foxglove WebSocket server on 127.0.0.1')
    discovery_period_s: float = setting(0.2, unit='s', low=0.01,
                                        doc='wall-clock period of the topic discovery poll')


class MarkerLayer:
    """Stable marker ids for the string ids of one namespace, and the deletions a set implies.

    Ids are handed out in order of first appearance and never reused, so an obstacle keeps
    its marker id for the whole run (and a reader can follow it from message to message).
    """

    def __init__(self) -> None:
        self._ids: dict[str, int] = {}
        self._shown: set[int] = set()

    def update(self, names: Iterable[str]) -> tuple[list[tuple[int, str]], list[int]]:
        """The set now holds ``names``: (marker id, name) to add, marker ids to delete."""
        present = [(self._ids.setdefault(name, len(self._ids)), name) for name in names]
        now = {marker_id for marker_id, _ in present}
        deleted = sorted(self._shown - now)
        self._shown = now
        return present, deleted


def outline(polygon: np.ndarray) -> np.ndarray:
    """(K + 1, 2) closed boundary of a (K, 2) polygon, for a LINE_STRIP."""
    polygon = np.asarray(polygon, dtype=float).reshape(-1, 2)
    return np.vstack([polygon, polygon[:1]]) if len(polygon) else polygon


def triangles(polygon: np.ndarray) -> np.ndarray:
    """(3T, 2) vertices of a triangulation of a simple polygon, for a TRIANGLE_LIST.

    Constrained Delaunay (GEOS), so a non-convex polygon is filled exactly, never over
    its notches; a degenerate polygon (fewer than three distinct vertices) gives none.
    """
    polygon = np.asarray(polygon, dtype=float).reshape(-1, 2)
    if len(polygon) < 3:
        return np.zeros((0, 2))
    shape = shapely.make_valid(shapely.Polygon(polygon))
    parts = shapely.get_parts(shapely.constrained_delaunay_triangles(shape))
    corners = [np.asarray(t.exterior.coords)[:3] for t in parts if t.area > 0.0]
    return np.vstack(corners) if corners else np.zeros((0, 2))


def shape_points(style: LayerStyle, polygon: np.ndarray) -> np.ndarray:
    """The marker's points (N, 2) for ``polygon`` in ``style``."""
    return triangles(polygon) if style.shape is Shape.FILL else outline(polygon)


class LegTargets:
    """The leg targets met so far, in order, and the current one."""

    def __init__(self) -> None:
        self.targets: list[tuple[float, float]] = []
        self._leg: int | None = None

    def update(self, leg_index: int, target: Sequence[float]) -> bool:
        """Record the controller's state; True when the drawing changed (a new leg)."""
        point = (float(target[0]), float(target[1]))
        if leg_index == self._leg and self.targets and self.targets[-1] == point:
            return False
        self._leg = leg_index
        if not self.targets or self.targets[-1] != point:
            self.targets.append(point)
        return True
