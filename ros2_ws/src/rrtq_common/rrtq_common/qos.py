"""QoS profiles of the rrtq topics, chosen per topic."""

from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)

# Per-step streams: reliable, with enough depth that a lock-step run at full speed
# never overwrites a sample a slow reader (the recorder) has not taken yet; transient
# local, so that a reader whose endpoint matches a moment late (discovery between two
# nodes can finish after the simulator's start-up check) still gets the first steps.
STREAM = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                    reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.TRANSIENT_LOCAL)
# State that a late joiner must get: latched (transient local), last value only.
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
# /clock: rclpy's time source subscribes best effort, depth 1; reliable offers match.
CLOCK = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                   reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.VOLATILE)
# A sensor stream read when paced (/scan): best effort, volatile, depth 5, as drivers offer
# it. It matches the simulator's reliable offer as well; a lock-step reader asks STREAM
# instead, since a step waits for its scan and a lost one would stall the run.
SENSOR_DATA = qos_profile_sensor_data
