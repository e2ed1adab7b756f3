"""QoS profiles of the rrtq topics, chosen per topic."""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Per-step streams: reliable, with enough depth that a lock-step run at full speed
# never overwrites a sample a slow reader (the recorder) has not taken yet.
STREAM = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                    reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)
# State that a late joiner must get: latched (transient local), last value only.
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
# /clock: rclpy's time source subscribes best effort, depth 1; reliable offers match.
CLOCK = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                   reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.VOLATILE)
