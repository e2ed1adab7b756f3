"""A node process exits even when the middleware's teardown hangs (rrtq_common.params.spin_node)."""

import os
import signal
import subprocess
import sys
import time

CHILD = """
import time
import rclpy
from rclpy.node import Node
from rrtq_common import params
params.TEARDOWN_S = 1.0
rclpy.try_shutdown = lambda *a, **k: time.sleep(120)    # a teardown that never returns
print('ready', flush=True)
params.spin_node(lambda: Node('stuck'))
"""


def test_a_hung_teardown_is_cut_short_after_its_bound():
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(100 + os.getpid() % 100))
    proc = subprocess.Popen([sys.executable, '-c', CHILD], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    assert proc.stdout.readline().strip() == 'ready'
    time.sleep(1.0)                                       # spinning
    proc.send_signal(signal.SIGTERM)
    start = time.monotonic()
    _, err = proc.communicate(timeout=30)
    assert time.monotonic() - start < 10.0                # not the 120 s of the hang
    assert proc.returncode == 0 and 'teardown took more than 1 s' in err
