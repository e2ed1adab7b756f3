"""Step joins: steps come out in order, complete, whatever order their inputs arrive in."""

import numpy as np

from rrtq_common.lockstep import Requirement, StampJoin, StepInputs

DT = 50_000_000


def test_stamp_join_completes_each_stamp_once():
    join = StampJoin(['a', 'b'])
    assert join.add('a', 0, 1) is None
    assert join.add('b', DT, 2) is None          # a later stamp can arrive first
    assert join.add('b', 0, 3) == {'a': 1, 'b': 3}
    assert join.add('a', 0, 4) is None           # late duplicate of a completed stamp
    assert join.add('a', DT, 5) == {'a': 5, 'b': 2}


def messages():
    """Two steps of a chain: status names a plan published at step 0 and again at step 1."""
    return [
        ('odom', 0, 'o0'), ('stats', 0, {'plan': 0}), ('plan', 0, 'p0'),
        ('dist', 0, 'd0'),
        ('odom', DT, 'o1'), ('stats', DT, {'plan': DT}), ('plan', DT, 'p1'),
        ('odom', 2 * DT, 'o2'), ('stats', 2 * DT, {'plan': DT}), ('dist', DT, 'd1'),
    ]


def test_steps_are_delivered_in_order_for_every_arrival_order():
    reqs = [Requirement('stats', followup='plan', names=lambda m: m['plan']),
            Requirement('dist', lag=1)]
    expected = [
        {'odom': 'o0', 'stamp_ns': 0, 'stats': {'plan': 0}, 'plan': 'p0', 'dist': None},
        {'odom': 'o1', 'stamp_ns': DT, 'stats': {'plan': DT}, 'plan': 'p1', 'dist': 'd0'},
        {'odom': 'o2', 'stamp_ns': 2 * DT, 'stats': {'plan': DT}, 'plan': 'p1', 'dist': 'd1'},
    ]
    rng = np.random.default_rng(0)
    for _ in range(200):
        # DDS keeps each topic in order; topics interleave arbitrarily.
        queues = {}
        for m in messages():
            queues.setdefault(m[0], []).append(m)
        order = []
        while any(queues.values()):
            key = rng.choice(sorted(k for k, q in queues.items() if q))
            order.append(queues[key].pop(0))
        inputs = StepInputs(reqs, DT)
        delivered = []
        for key, stamp, msg in order:
            inputs.add(key, stamp, msg)
            delivered += inputs.pop_ready()
        assert delivered == expected


def test_a_step_waits_for_the_plan_its_status_names():
    inputs = StepInputs([Requirement('stats', followup='plan', names=lambda m: m['plan'])], DT)
    inputs.add('odom', 0, 'o0')
    inputs.add('stats', 0, {'plan': 0})
    assert inputs.pop_ready() == []
    inputs.add('plan', 0, 'p0')
    assert [v['plan'] for v in inputs.pop_ready()] == ['p0']
