"""Topic names of the rrtq graph (docs/design.md, "Node graph and topics")."""

CLOCK = '/clock'
ODOM = '/odom'
# The simulator's true state, for the simulator's side (spawner, injector, referee) and the
# recording: no robot node reads it.
ODOM_TRUTH = '/odom/truth'
CMD_FORCE = '/cmd_force'
DISTURBANCE = '/disturbance'
GOAL_POSE = '/goal_pose'
OBSTACLES_DETECTED = '/obstacles/detected'
# perception.source: scan: the simulated laser scan (sensor_msgs/LaserScan, frame base_link),
# read by the robot's obstacle mapper, which then writes /obstacles/detected.
SCAN = '/scan'
OBSTACLES_AUGMENTED = '/obstacles/augmented'
PLAN = '/plan'
PLANNER_TREE = '/planner/tree'
PLANNER_STATS = '/planner/stats'
CONTROLLER_STATE = '/controller/state'
SAFETY_STATUS = '/safety/status'
DISTURBANCE_ESTIMATE = '/safety/disturbance_estimate'
PERCEPTION_STATUS = '/perception/status'
OBSTACLES_TRUTH = '/obstacles/truth'
REFEREE_STATUS = '/referee/status'
PLANT_CONTACT = '/plant/contact'
SIMULATOR_PAUSE = '/simulator/pause'
GUIDANCE_REFERENCE = '/guidance/reference'
# The start-up handshake (rrtq_common.readiness): each writer of per-step topics, once connected.
GRAPH_READY = '/graph/ready'
# Written for people only, by the visualisation node (rrtq_bringup.viz_node): no node reads them.
TF = '/tf'
VIZ_TRUTH = '/viz/obstacles/truth'
VIZ_DETECTED = '/viz/obstacles/detected'
VIZ_AUGMENTED = '/viz/obstacles/augmented'
VIZ_ROBOT = '/viz/robot'
VIZ_LEG_TARGETS = '/viz/leg_targets'
