"""Topic names of the rrtq graph (DESIGN.md, "Node graph and topics")."""

CLOCK = '/clock'
ODOM = '/odom'
CMD_FORCE = '/cmd_force'
DISTURBANCE = '/disturbance'
GOAL_POSE = '/goal_pose'
OBSTACLES_DETECTED = '/obstacles/detected'
OBSTACLES_AUGMENTED = '/obstacles/augmented'
PLAN = '/plan'
PLANNER_TREE = '/planner/tree'
PLANNER_STATS = '/planner/stats'
CONTROLLER_STATE = '/controller/state'
SAFETY_STATUS = '/safety/status'
