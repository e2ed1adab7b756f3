"""Guiding level of VF-LPC (§IV-A): the kinodynamic composite guiding vector field.

Pure numpy: the desired path (the RRT^X path) and the augmented obstacles in, a
reference trajectory (positions and velocities every dt) out. See docs/vf_lpc.md.
"""

from .config import CurveStatus, GuidanceConfig, GuidanceMode
from .curve import Curve, Reference, integral_curve, menger_curvature, sample_in_time, \
    speed_profile
from .field import CompositeField, RolloutState, VirtualObstacle, bump_weights, \
    place_virtual_obstacles
from .obstacles import PolygonDistances
from .path import FilletedPath, PathQuery
from .session import GuidanceOutput, GuidanceSession, ReferenceStatus
from .track import GuidanceTrack

__all__ = ['CompositeField', 'Curve', 'CurveStatus', 'FilletedPath', 'GuidanceConfig',
           'GuidanceMode', 'GuidanceOutput', 'GuidanceSession', 'GuidanceTrack', 'PathQuery',
           'PolygonDistances', 'Reference', 'ReferenceStatus', 'RolloutState',
           'VirtualObstacle', 'bump_weights', 'integral_curve', 'menger_curvature',
           'place_virtual_obstacles', 'sample_in_time', 'speed_profile']
