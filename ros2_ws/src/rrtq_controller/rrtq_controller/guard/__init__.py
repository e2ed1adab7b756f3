"""Guards of safe learning (beyond the papers): trust region, divergence watch, brake, keep-off.

The papers' actor follows the critic's greedy policy at every step. Where the critic was
fitted to little data (the first legs from a zero gain, one direction of motion), its
cross terms Q̂_ux are poorly identified and the greedy gain can be arbitrarily large: on
the rover without a spring the first greedy policy once commanded -3.2e5 N. The
controller therefore adopts a new actor target only when it passes stated checks
(:meth:`rrtq_controller.policy_iteration.PolicyIteration.policy_improvement`), bounds
each change (:func:`trust_step`), and watches every leg for divergence
(:class:`DivergenceWatch`), reverting to the last policy that completed a leg
(:mod:`.policy`); where no policy is known to work, or the robot nears an obstacle, it
pushes with forces adapted on line (:class:`Brake`, :class:`KeepOff`: :mod:`.forces`).
Everything here is model-free: it uses the data, the cost weights and the actuator's
limit, never the plant's matrices.
"""

from .forces import Brake, KeepOff, Sensing, face_ahead, slowing_too_little
from .policy import FALSE_ALARM, DivergenceWatch, PolicyEvent, held_below, trust_step

__all__ = ['FALSE_ALARM', 'Brake', 'DivergenceWatch', 'KeepOff', 'PolicyEvent', 'Sensing',
           'face_ahead', 'held_below', 'slowing_too_little', 'trust_step']
